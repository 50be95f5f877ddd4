"""On a machine without the system parts that pip cannot install
(Chromium, iptables, a Vulkan driver), the tests that need them skip, each
saying what to install, and none fails. Checked by hiding those parts from
a pytest run of those tests: a PATH with only this environment's programs,
and a Vulkan loader pointed at no driver."""

import os
import re
import subprocess
import sys
from pathlib import Path

ROOT = Path(__file__).resolve().parent.parent
NEEDING = (
    "tests/test_browser_phone.py",
    "tests/test_viewer.py::test_pictures_at_two_times_show_north_up_and_each_agent_where_it_was",
    "tests/test_viewer.py::test_a_time_after_the_end_or_without_a_picture_is_refused_in_one_sentence",
    "tests/test_kernel_network.py",
    "tests/test_transport.py::test_fixes_travel_over_udp_and_state_over_tcp",
    "tests/test_fault_suites.py::test_a_partition_on_a_kernel_network_is_noticed_at_the_lease_and_healed",
)


def test_tests_needing_what_the_machine_lacks_skip_saying_what_to_install(tmp_path):
    hidden = dict(os.environ, PATH=str(Path(sys.executable).parent), VK_DRIVER_FILES=str(tmp_path / "no-driver.json"))
    hidden.pop("VK_ICD_FILENAMES", None)
    run = subprocess.run(
        [sys.executable, "-m", "pytest", "-n", "0", "-p", "no:cacheprovider", "-q", "-rs", *NEEDING],
        cwd=ROOT,
        env=hidden,
        capture_output=True,
        text=True,
        timeout=300,
    )
    assert run.returncode == 0, run.stdout[-3000:]
    summary = run.stdout.strip().splitlines()[-1]
    assert re.fullmatch(r"=* ?\d+ skipped in [\d.]+s ?=*", summary), summary
    reasons = [line for line in run.stdout.splitlines() if line.startswith("SKIPPED")]
    assert reasons
    for line in reasons:
        assert "install" in line or "root" in line, line
    said = "\n".join(reasons)
    assert "apt-get install chromium" in said
    assert "apt-get install mesa-vulkan-drivers" in said
    assert "iptables" in said
