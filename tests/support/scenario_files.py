"""A small capture-the-flag scenario for the field-simulator tests: the
fake-out setup of thesis 3.5.1 on a 21 x 21 grid, which solves in seconds,
with the thesis's guidance (answers at the reports) unless ``method``
says otherwise."""

SCENARIO = """
[scenario]
name = "{name}"
map = "field-50"
game = "ctf"
time_limit = {time_limit}
netem = "{netem}"
seed = 3
lease = {lease}

[rules]
capture_radius = 2.5
stages = "return"
grid = 21
return_time = 60.0

[guidance]
method = "{method}"

[[agent]]
id = "attacker"
team = "attacker"
start = {attacker}
speed = 3.0
behaviour = "{attacker_behaviour}"
aided = true

[[agent]]
id = "defender"
team = "defender"
start = {defender}
speed = 3.0
behaviour = "{defender_behaviour}"
aided = {defender_aided}
"""


def scenario_text(
    name="test-game",
    *,
    time_limit=30.0,
    netem="wifi",
    attacker=(25.0, 22.0),
    defender=(25.0, 34.0),
    attacker_behaviour="fake-out",
    defender_behaviour="direct",
    defender_aided=False,
    method="none",
    lease=10.0,
) -> str:
    return SCENARIO.format(
        name=name,
        time_limit=time_limit,
        netem=netem,
        attacker=list(attacker),
        defender=list(defender),
        attacker_behaviour=attacker_behaviour,
        defender_behaviour=defender_behaviour,
        defender_aided=str(defender_aided).lower(),
        method=method,
        lease=lease,
    )


def write_scenario(directory, **kw):
    path = directory / "game.toml"
    path.write_text(scenario_text(**kw))
    return path
