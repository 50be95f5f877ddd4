"""The access control list a ``--secure`` router enforces, from the policy.

Zenoh's router checks each message against rules by the common name of the
certificate the sender's TLS link presented, with everything not allowed
denied: what a peer may put (ingress), what it may be sent (egress), which
subscriptions, queryables, queries and liveliness tokens it may declare.
A subscription must name keys the rules allow whole: Zenoh refuses a
wildcard they allow only in part, so peers subscribe to exact keys.
"""

from __future__ import annotations

from bearcat.bus import keys
from bearcat.bus.policy import publishes, reads, watches

_PUBLISHER = {"put": "ingress"}
_READER = {"declare_subscriber": "ingress", "put": "egress"}
_WATCHER = {"declare_liveliness_subscriber": "ingress", "liveliness_query": "ingress", "liveliness_token": "egress"}
_TOKEN = {"liveliness_token": "ingress", "declare_liveliness_subscriber": "egress", "liveliness_query": "egress"}
_SERVER = {"declare_queryable": "ingress", "query": "egress", "reply": "ingress"}
_ASKER = {"query": "ingress", "reply": "egress", "declare_queryable": "egress"}


def access_control(game: str, members: dict[str, str]) -> dict:
    """Zenoh's ``access_control`` section for ``game`` with ``members`` (name -> role)."""
    rules, subjects, policies = [], [], []
    for name, role in sorted(members.items()):
        grants = [
            ("publish", _PUBLISHER, publishes(role, name, game)),
            ("read", _READER, reads(role, name, game)),
            ("watch", _WATCHER, watches(role, name, game)),
            ("token", _TOKEN, _tokens(role, name, game)),
            ("ask", _ASKER, _served(game)),
        ]
        if role == "ground-station":
            grants.append(("serve", _SERVER, _served(game)))
        elif role == "launcher":
            grants.append(("hand-in", _ASKER, [keys.every(game, "log")]))
        else:
            grants.append(("hand-in", _SERVER, [keys.log_query(game, name)]))
        # A publisher learns who subscribes (and so whether to send at all)
        # from the subscriptions the router passes on, which name wildcards
        # (the ground station's every fix): it hears of them all. They name
        # keys, never what is said on them.
        grants.append(("learn", {"declare_subscriber": "egress"}, [keys.game_wide(game)]))
        ids = []
        for what, messages, key_exprs in grants:
            if not key_exprs:
                continue
            for flow in ("ingress", "egress"):
                chosen = sorted(m for m, f in messages.items() if f == flow)
                if chosen:
                    ids.append(f"{name}-{what}-{flow}")
                    rules.append(
                        {
                            "id": ids[-1],
                            "permission": "allow",
                            "flows": [flow],
                            "messages": chosen,
                            "key_exprs": key_exprs,
                        }
                    )
        subjects.append({"id": name, "cert_common_names": [name]})
        policies.append({"rules": ids, "subjects": [name]})
    return {
        "enabled": True,
        "default_permission": "deny",
        "rules": rules,
        "subjects": subjects,
        "policies": policies,
    }


def _served(game: str) -> list[str]:
    """What the ground station serves a peer started elsewhere: the map, the scenario and the fault plan."""
    return [keys.map_query(game), keys.scenario_query(game), keys.plan_query(game)]


def _tokens(role: str, name: str, game: str) -> list[str]:
    """The liveliness tokens ``name`` may declare: its own (the ground station's services, any role's)."""
    if role in ("ground-station", "launcher"):
        return [keys.every(game, "alive")]
    return [keys.alive(game, role, name)]
