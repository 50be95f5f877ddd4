"""The parts of the operating system some tests need beyond what pip
installs: a browser, iptables and root, a Vulkan driver. Each check returns
None, or the one sentence a skip says: what is missing and how to get it,
so that the suite passes on a bare machine and says what it left out."""

from __future__ import annotations

import ctypes.util
import os
import shutil
from pathlib import Path

CHROMIUM = Path("/usr/lib/chromium/chromium")
"""Debian's Chromium binary, which Playwright drives (its own browser download is not reachable)."""

ICD_FOLDERS = ("/usr/share/vulkan/icd.d", "/usr/local/share/vulkan/icd.d", "/etc/vulkan/icd.d")
"""Where the Vulkan loader looks for drivers when no variable names them."""


def missing_chromium() -> str | None:
    if shutil.which("chromium") is None or not CHROMIUM.exists():
        return "needs Chromium for the phone's page: apt-get install chromium"
    try:
        import playwright.sync_api  # noqa: F401
    except ImportError:
        return "needs Playwright to drive Chromium: pip install -e '.[test]'"
    return None


def missing_iptables() -> str | None:
    if os.geteuid() != 0:
        return "needs root for iptables: run the tests as root"
    if shutil.which("iptables") is None:
        return "needs iptables: apt-get install iptables"
    return None


def missing_namespaces() -> str | None:
    """What stands in the way of network namespaces standing in for other computers."""
    if os.geteuid() != 0:
        return "needs root for network namespaces and veth pairs (they stand in for other computers): run as root"
    absent = [tool for tool in ("ip", "unshare", "nsenter") if shutil.which(tool) is None]
    if absent:
        return f"needs {', '.join(absent)} for network namespaces: apt-get install iproute2 util-linux"
    return None


def missing_kernel_network() -> str | None:
    """What kernel mode lacks here (root, iproute2, iptables, netfilterqueue), in its own words."""
    from bearcat.netem.kernel.network import missing

    return missing()


def missing_vulkan() -> str | None:
    """The headless Rerun viewer renders through Vulkan: a loader and at least one driver it would find."""
    if ctypes.util.find_library("vulkan") is None:
        return "needs a Vulkan driver for the headless Rerun viewer: apt-get install mesa-vulkan-drivers"
    named = os.environ.get("VK_DRIVER_FILES") or os.environ.get("VK_ICD_FILENAMES")
    if named is not None:
        drivers = [Path(p) for p in named.split(os.pathsep) if p and Path(p).exists()]
    else:
        folders = list(ICD_FOLDERS) + [
            str(Path(d) / "vulkan" / "icd.d") for d in os.environ.get("XDG_DATA_DIRS", "").split(os.pathsep) if d
        ]
        drivers = [f for folder in folders for f in Path(folder).glob("*.json")]
    if not drivers:
        return "needs a Vulkan driver for the headless Rerun viewer: apt-get install mesa-vulkan-drivers"
    return None
