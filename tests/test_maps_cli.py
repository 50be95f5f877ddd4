"""`bearcat maps` as a user runs it: a separate process, exit codes, stdout and stderr."""

import json
import subprocess
import sys
from pathlib import Path

from bearcat.maps import list_maps

ROOT = Path(__file__).resolve().parents[1]


def bearcat(*args: str) -> subprocess.CompletedProcess:
    return subprocess.run(
        [sys.executable, "-m", "bearcat", *args], cwd=ROOT, capture_output=True, text=True, timeout=60
    )


def test_list_prints_one_line_per_built_in_map():
    result = bearcat("maps", "list")
    assert result.returncode == 0, result.stderr
    lines = result.stdout.splitlines()
    assert [line.split()[0] for line in lines] == list_maps()
    campus = next(line for line in lines if line.startswith("campus-400"))
    assert "400 x 400 m" in campus and "flag, home" in campus


def test_show_json_gives_bounds_and_regions():
    result = bearcat("maps", "show", "field-50", "--json")
    assert result.returncode == 0, result.stderr
    shown = json.loads(result.stdout)
    assert shown["name"] == "field-50"
    assert shown["bounds"] == [0, 0, 50, 50]
    assert shown["regions"]["home"]["role"] == "return"
    assert shown["regions"]["home"]["bounds"] == [0, 45, 50, 50]
    assert shown["origin"].keys() == {"lat", "lon"} and shown["obstacles"] == 0


def test_show_summary_without_options():
    result = bearcat("maps", "show", "campus-200")
    assert result.returncode == 0, result.stderr
    assert result.stdout.startswith("campus-200: ") and "200 x 180 m" in result.stdout


def test_unknown_map_is_one_sentence_and_exit_code_2():
    result = bearcat("maps", "show", "nosuchmap")
    assert result.returncode == 2
    assert "Traceback" not in result.stderr
    assert result.stderr.count("\n") == 1 and "nosuchmap" in result.stderr and "campus-400" in result.stderr


def test_show_draws_a_png(tmp_path):
    out = tmp_path / "map.png"
    result = bearcat("maps", "show", "field-50", "-o", str(out))
    assert result.returncode == 0, result.stderr
    assert out.read_bytes()[:8] == b"\x89PNG\r\n\x1a\n"


def test_show_reads_a_user_file(tmp_path):
    path = tmp_path / "yard.geojson"
    path.write_text(
        json.dumps(
            {
                "type": "FeatureCollection",
                "bearcat": {"units": "metres", "origin": {"lat": 37.87, "lon": -122.26}},
                "features": [
                    {
                        "type": "Feature",
                        "properties": {"kind": "area"},
                        "geometry": {"type": "Polygon", "coordinates": [[[0, 0], [30, 0], [30, 20], [0, 20], [0, 0]]]},
                    }
                ],
            }
        )
    )
    result = bearcat("maps", "show", str(path), "--json")
    assert result.returncode == 0, result.stderr
    assert json.loads(result.stdout)["bounds"] == [0, 0, 30, 20]
    path.write_text("{")
    result = bearcat("maps", "show", str(path))
    assert result.returncode == 2 and str(path) in result.stderr and "Traceback" not in result.stderr
