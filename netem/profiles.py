"""Named impairment profiles, read from ``profiles.toml`` beside this module
(or any file of the same form); errors name the file, the profile and the key."""

from __future__ import annotations

import math
import tomllib
from dataclasses import dataclass, field, fields
from importlib import resources
from pathlib import Path

from bearcat.netem.models import DISTRIBUTIONS, CompassError, Delay, GilbertElliott, GpsError, LinkModel, Outage


class ProfileError(ValueError):
    """A bad profile name or profile file; the text names the culprit."""


@dataclass(frozen=True)
class Profile:
    name: str
    description: str = ""
    sources: tuple[str, ...] = ()
    link: LinkModel = field(default_factory=LinkModel)
    gps: GpsError = field(default_factory=GpsError)
    compass: CompassError = field(default_factory=CompassError)


_LINK_KEYS = {
    "delay",
    "jitter",
    "distribution",
    "loss",
    "burst",
    "duplicate",
    "reorder",
    "rate",
    "idle_after",
    "promotion",
    "outages",
    "retransmit",
}
_PROBABILITIES = {"loss", "duplicate", "reorder", "dropout", "urban_dropout"}


def builtin_path():
    return resources.files("bearcat.netem") / "profiles.toml"


def load_profiles(path: str | Path | None = None) -> dict[str, Profile]:
    source = builtin_path() if path is None else Path(path)
    where = "netem/profiles.toml" if path is None else str(path)
    try:
        data = tomllib.loads(source.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ProfileError(f"there is no profile file {where}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ProfileError(f"{where} is not valid TOML: {exc}") from None
    return {name: _profile(name, table, where) for name, table in data.items()}


def load_profile(name: str, path: str | Path | None = None) -> Profile:
    profiles = load_profiles(path)
    if name not in profiles:
        raise ProfileError(f"there is no netem profile {name!r}; the profiles are {', '.join(profiles)}")
    return profiles[name]


def _profile(name: str, table, where: str) -> Profile:
    at = f"{where} [{name}]"
    if not isinstance(table, dict):
        raise ProfileError(f"{at} must be a table")
    _only(table, {"description", "sources", "link", "gps", "compass"}, at)
    link = table.get("link", {})
    _only(link, _LINK_KEYS, f"{at}.link")
    burst = link.get("burst")
    if burst is not None:
        _only(burst, {"p", "r", "loss_good", "loss_bad"}, f"{at}.link.burst")
        burst = GilbertElliott(**{k: _number(v, f"{at}.link.burst.{k}", probability=True) for k, v in burst.items()})
    distribution = link.get("distribution", "normal")
    if distribution not in DISTRIBUTIONS:
        raise ProfileError(f"{at}.link.distribution is {distribution!r}, not one of {', '.join(DISTRIBUTIONS)}")
    promotion = link.get("promotion", [0.0, 0.0])
    if not (isinstance(promotion, list) and len(promotion) == 2):
        raise ProfileError(f"{at}.link.promotion must be [shortest, longest] in seconds")
    lo, hi = (_number(v, f"{at}.link.promotion") for v in promotion)
    if hi < lo:
        raise ProfileError(f"{at}.link.promotion has its longest below its shortest")
    outages = []
    for k, window in enumerate(link.get("outages", [])):
        if not (isinstance(window, list) and len(window) == 2):
            raise ProfileError(f"{at}.link.outages[{k}] must be [start, end] in seconds")
        start, end = (_number(v, f"{at}.link.outages[{k}]") for v in window)
        outages.append(Outage(start, end))
    numbers = {
        k: _number(link[k], f"{at}.link.{k}", probability=k in _PROBABILITIES)
        for k in ("loss", "duplicate", "reorder", "rate", "idle_after", "retransmit")
        if k in link
    }
    model = LinkModel(
        delay=Delay(
            _number(link.get("delay", 0.0), f"{at}.link.delay"),
            _number(link.get("jitter", 0.0), f"{at}.link.jitter"),
            distribution,
        ),
        burst=burst,
        promotion=(lo, hi),
        outages=tuple(outages),
        **numbers,
    )
    return Profile(
        name=name,
        description=str(table.get("description", "")),
        sources=tuple(str(s) for s in table.get("sources", [])),
        link=model,
        gps=_struct(GpsError, table.get("gps", {}), f"{at}.gps"),
        compass=_struct(CompassError, table.get("compass", {}), f"{at}.compass"),
    )


def _struct(cls, table, at: str):
    _only(table, {f.name for f in fields(cls)}, at)
    return cls(**{k: _number(v, f"{at}.{k}", probability=k in _PROBABILITIES) for k, v in table.items()})


def _only(table, allowed: set[str], at: str) -> None:
    if not isinstance(table, dict):
        raise ProfileError(f"{at} must be a table")
    for key in table:
        if key not in allowed:
            raise ProfileError(f"{at} has no key {key!r}; the keys are {', '.join(sorted(allowed))}")


def _number(value, at: str, *, probability: bool = False) -> float:
    if isinstance(value, bool) or not isinstance(value, int | float) or not math.isfinite(value) or value < 0:
        raise ProfileError(f"{at} must be a non-negative number, got {value!r}")
    if probability and value > 1:
        raise ProfileError(f"{at} is a probability and must lie in [0, 1], got {value!r}")
    return float(value)
