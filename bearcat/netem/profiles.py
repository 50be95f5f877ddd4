"""Named impairment profiles, read from ``profiles.toml`` beside this module
(or any file of the same form). The tables below and the models' own
Structs are the file's schema, bounds and defaults; errors are one sentence
naming the file, the profile and the key, such as
``p.toml: 3g.link.loss: must be a probability in [0, 1], got 1.5``."""

from __future__ import annotations

import tomllib
from dataclasses import dataclass
from importlib import resources
from pathlib import Path
from typing import Annotated

import msgspec
from msgspec import Meta

from bearcat.netem.models import (
    CompassError,
    Delay,
    Distribution,
    GilbertElliott,
    GpsError,
    LinkModel,
    Outage,
    Probability,
)
from bearcat.validation import Invalid, convert


class ProfileError(ValueError):
    """A bad profile name or profile file; the text names the culprit."""


@dataclass(frozen=True)
class Profile:
    name: str
    description: str
    sources: tuple[str, ...]
    link: LinkModel
    gps: GpsError
    compass: CompassError


Lag = Annotated[float, Meta(ge=0.0, le=60.0, extra={"unit": "s"})]
GameTime = Annotated[float, Meta(ge=0.0, le=86400.0, extra={"unit": "s"})]


class LinkTable(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """``[NAME.link]``: a ``LinkModel`` written flat, its defaults the model's."""

    delay: Lag = Delay.base
    jitter: Lag = Delay.jitter
    distribution: Distribution = Delay.distribution
    jitter_time: Lag = LinkModel.jitter_time
    loss: Probability = LinkModel.loss
    burst: GilbertElliott | None = LinkModel.burst
    duplicate: Probability = LinkModel.duplicate
    reorder: Probability = LinkModel.reorder
    rate: Annotated[float, Meta(ge=0.0, le=1e12, extra={"unit": "bytes/s"})] = LinkModel.rate
    idle_after: Annotated[float, Meta(ge=0.0, le=3600.0, extra={"unit": "s"})] = LinkModel.idle_after
    promotion: Annotated[tuple[Lag, Lag], Meta(description="[shortest, longest] in seconds")] = LinkModel.promotion
    outages: tuple[Annotated[tuple[GameTime, GameTime], Meta(description="[start, end] in seconds")], ...] = ()


class ProfileTable(msgspec.Struct, frozen=True, forbid_unknown_fields=True, kw_only=True):
    """``[NAME]`` with its ``[NAME.link]``, ``[NAME.gps]`` and ``[NAME.compass]``."""

    description: str = ""
    sources: tuple[str, ...] = ()
    link: LinkTable = LinkTable()
    gps: GpsError = GpsError()
    compass: CompassError = CompassError()


def builtin_path():
    return resources.files("bearcat.netem") / "profiles.toml"


def load_profiles(path: str | Path | None = None) -> dict[str, Profile]:
    source = builtin_path() if path is None else Path(path)
    where = "netem/profiles.toml" if path is None else str(path)
    try:
        data = tomllib.loads(source.read_text(encoding="utf-8"))
    except FileNotFoundError:
        raise ProfileError(f"there is no profile file {where}") from None
    except UnicodeDecodeError:
        raise ProfileError(f"{where} is not UTF-8 text") from None
    except OSError as exc:
        raise ProfileError(f"{where} cannot be read: {exc.strerror}") from None
    except tomllib.TOMLDecodeError as exc:
        raise ProfileError(f"{where} is not valid TOML: {exc}") from None
    except RecursionError:
        raise ProfileError(f"{where} nests arrays or tables too deeply to be a profile file") from None
    profiles = {}
    for name, table in data.items():
        try:
            given = convert(table, ProfileTable, at=name)
            link = _link_model(given.link, f"{name}.link")
        except Invalid as exc:
            raise ProfileError(f"{where}: {exc}") from None
        profiles[name] = Profile(name, given.description, given.sources, link, given.gps, given.compass)
    return profiles


def load_profile(name: str, path: str | Path | None = None) -> Profile:
    profiles = load_profiles(path)
    if name not in profiles:
        raise ProfileError(f"there is no netem profile {name!r}; the profiles are {', '.join(profiles)}")
    return profiles[name]


def _link_model(link: LinkTable, at: str) -> LinkModel:
    """The link ``link`` describes; an ``Invalid`` for windows that end before they begin."""
    shortest, longest = link.promotion
    if longest < shortest:
        raise Invalid(f"{at}.promotion", f"has its longest, {longest:g} s, below its shortest, {shortest:g} s")
    for k, (start, end) in enumerate(link.outages):
        if end < start:
            raise Invalid(f"{at}.outages[{k}]", f"ends at {end:g} s, before it starts at {start:g} s")
    return LinkModel(
        delay=Delay(link.delay, link.jitter, link.distribution),
        jitter_time=link.jitter_time,
        loss=link.loss,
        burst=link.burst,
        duplicate=link.duplicate,
        reorder=link.reorder,
        rate=link.rate,
        idle_after=link.idle_after,
        promotion=link.promotion,
        outages=tuple(Outage(start, end) for start, end in link.outages),
    )
