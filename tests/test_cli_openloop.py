"""``bearcat solve openloop`` as a user runs it: a real process, real files."""

from __future__ import annotations

import json
import subprocess
import sys

import numpy as np
import pytest
import shapely

from bearcat.maps import load_map


def bearcat(*words: str, cwd=None) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "bearcat", *words], capture_output=True, text=True, timeout=300, cwd=cwd
    )


CAMPUS = ("solve", "openloop", "--map", "campus-400", "--target", "flag", "home", "--stage-speed", "5", "2")


def test_two_stage_campus_solve_writes_a_safe_path_json_and_plot(tmp_path):
    out_json, out_png = tmp_path / "result.json", tmp_path / "result.png"
    run = bearcat(
        *CAMPUS,
        "--attacker",
        "370,30",
        "--defender",
        "120,150",
        "--defender",
        "330,200,0.5",
        "--capture-radius",
        "2",
        "--json",
        str(out_json),
        "--plot",
        str(out_png),
    )
    assert run.returncode == 0, run.stderr
    assert "safe path found" in run.stdout
    report = json.loads(out_json.read_text())
    assert report["reached"] is True and report["blocked_stage"] is None
    first, second = report["stages"]
    assert 0 < first["value_s"] < second["value_s"] == report["value_s"]
    assert first["safe_area_m2"] > 0 and second["safe_area_m2"] > 0
    start = first["path"]["points"][0]
    assert np.hypot(start[0] - 370, start[1] - 30) < 1.0
    assert first["path"]["points"][-1] == second["path"]["points"][0]
    campus = load_map("campus-400")
    end = shapely.Point(second["path"]["points"][-1])
    assert campus.region("home").geometry.distance(end) < 1.5
    times = first["path"]["times_s"] + second["path"]["times_s"][1:]
    assert np.all(np.diff(times) >= 0) and times[-1] == pytest.approx(second["value_s"], abs=0.5)
    assert out_png.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_a_defender_on_the_target_leaves_no_safe_path(tmp_path):
    out_json = tmp_path / "result.json"
    run = bearcat(
        "solve",
        "openloop",
        "--map",
        "square-10",
        "--attacker",
        "1,1",
        "--defender",
        "8,8",
        "--target",
        "8.5,8.5,0.5",
        "--capture-radius",
        "0.5",
        "--json",
        str(out_json),
    )
    assert run.returncode == 0, run.stderr
    assert "no safe path" in run.stdout
    report = json.loads(out_json.read_text())
    assert report["reached"] is False and report["blocked_stage"] == 1 and report["value_s"] is None


def _inside_an_obstacle(name: str) -> str:
    point = load_map(name).obstacles[0].representative_point()
    return f"{point.x},{point.y}"


@pytest.mark.parametrize(
    "words, culprit",
    [
        (("--map", "atlantis", "--attacker", "1,1", "--target", "5,5,1"), "atlantis"),
        (("--map", "square-10", "--attacker", "1,1", "--target", "50,50,1"), "target 1"),
        (("--map", "square-10", "--attacker", "1,1", "--target", "moon"), "moon"),
        (("--map", "triangle-10", "--attacker", _inside_an_obstacle("triangle-10"), "--target", "9,9,1"), "attacker"),
        (("--map", "square-10", "--attacker", "1,1", "--defender", "20,5", "--target", "9,9,1"), "defender 1"),
        (("--map", "square-10", "--attacker", "1,1", "--target", "9,9,1", "--stage-speed", "0"), "'0'"),
        (("--map", "square-10", "--attacker", "1,1", "--defender", "5,5,-1", "--target", "9,9,1"), "5,5,-1"),
        (("--map", "square-10", "--attacker", "nan,1", "--target", "9,9,1"), "nan,1"),
        (
            ("--map", "square-10", "--attacker", "1,1", "--target", "9,9,1", "5,5,1", "--stage-speed", "1", "2", "3"),
            "--stage-speed",
        ),
    ],
)
def test_bad_input_is_one_sentence_naming_the_culprit_and_exit_code_2(words, culprit):
    run = bearcat("solve", "openloop", *words)
    assert run.returncode == 2
    assert "Traceback" not in run.stderr
    message = run.stderr.strip().splitlines()[-1]
    assert "error" in message and culprit in message


def test_a_users_geojson_file_works_wherever_a_built_in_name_does(tmp_path):
    from bearcat.maps import write_geojson

    field = tmp_path / "my-field.geojson"
    write_geojson(load_map("field-50"), field)
    by_name = bearcat(
        "solve",
        "openloop",
        "--map",
        "field-50",
        "--attacker",
        "40,5",
        "--target",
        "home",
        "--defender",
        "5,20",
        "--capture-radius",
        "1",
        "--json",
        "-",
    )
    by_path = bearcat(
        "solve",
        "openloop",
        "--map",
        str(field),
        "--attacker",
        "40,5",
        "--target",
        "home",
        "--defender",
        "5,20",
        "--capture-radius",
        "1",
        "--json",
        "-",
    )
    assert by_name.returncode == by_path.returncode == 0, by_path.stderr
    value = [json.loads(run.stdout[run.stdout.index("{") :])["value_s"] for run in (by_name, by_path)]
    assert value[0] is not None and value[0] == pytest.approx(value[1], abs=1e-3)
