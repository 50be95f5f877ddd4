"""The README's Python examples run as written, so the API they show is the
API there is; the schema error they quote is the one the command prints."""

import re
import subprocess
import sys
from pathlib import Path

import pytest

README = (Path(__file__).resolve().parent.parent / "README.md").read_text()
EXAMPLES = re.findall(r"```python\n(.*?)```", README, flags=re.S)


def test_the_readme_has_python_examples():
    assert len(EXAMPLES) >= 3


@pytest.mark.slow  # the capture-the-flag example solves two 45^4 sets, about a minute
@pytest.mark.parametrize("code", EXAMPLES, ids=[f"example-{k}" for k in range(len(EXAMPLES))])
def test_a_readme_example_runs(code):
    exec(compile(code, "README.md", "exec"), {})


def test_the_quoted_schema_error_is_what_the_command_prints(tmp_path):
    quoted = re.search(r"^\$ bearcat simulate game\.toml\n(bearcat: error: game\.toml: .*)$", README, flags=re.M)
    assert quoted, "the README quotes a schema error"
    scenario = (Path(__file__).resolve().parent.parent / "scenarios" / "data" / "fake-out.toml").read_text()
    (tmp_path / "game.toml").write_text(scenario.replace('behaviour = "fake-out"', 'behaviour = "fakeout"', 1))
    run = subprocess.run(
        [sys.executable, "-m", "bearcat", "simulate", "game.toml"], cwd=tmp_path, capture_output=True, text=True
    )
    assert run.returncode == 2
    assert run.stderr.strip() == quoted.group(1)
