#!/usr/bin/env bash
# The live and network tests on a machine kept busy: one process per core
# spins at the tests' own priority for as long as they run, as a study or a
# browser beside the suite would. A test that waits on the wall clock must
# take its bound from what it waits for, so this slows the suite but cannot
# fail it.
#
#   bash tests/stress.sh                 # the live and network tests, under load
#   bash tests/stress.sh -k crash        # pytest's own options pass through
set -euo pipefail
cd "$(dirname "${BASH_SOURCE[0]}")/.."

python=${PYTHON:-python}
spinners=()
stop_spinning() {
    if ((${#spinners[@]})); then
        kill "${spinners[@]}" 2>/dev/null || true
        wait "${spinners[@]}" 2>/dev/null || true
    fi
}
trap stop_spinning EXIT
for _ in $(seq "$(nproc)"); do
    "$python" -c "while True: pass" &
    spinners+=($!)
done

live_and_network=(
    tests/test_live.py tests/test_live_run.py tests/test_crashes.py tests/test_resume.py
    tests/test_fault_suites.py tests/test_kernel_network.py tests/test_field_network.py
    tests/test_page_bridge.py tests/test_browser_phone.py tests/test_remote.py tests/test_uav.py
    tests/test_transport.py tests/test_bus.py tests/test_secure.py tests/test_attacks.py
    tests/test_leftovers.py tests/test_provisional.py tests/test_plugins.py
)
"$python" -m pytest "${live_and_network[@]}" "$@"
