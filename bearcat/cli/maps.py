"""``bearcat maps``: list the built-in maps, show one as a summary, JSON or picture."""

from __future__ import annotations

from bearcat.cli.arguments import Commands
from bearcat.cli.output import Output
from bearcat.maps import Map, list_maps, load_map


def register(commands: Commands) -> None:
    parser = commands.add_parser("maps", description="List the built-in maps, or show one as text, JSON or a picture.")
    actions = parser.add_subparsers(dest="maps_command", metavar="SUBCOMMAND", required=True)

    listing = actions.add_parser("list", help="one line per built-in map")
    listing.set_defaults(run=run_list)

    show = actions.add_parser("show", help="describe a map, print it as JSON or draw it")
    show.add_argument("map", metavar="NAME_OR_PATH", help="a built-in map name or a GeoJSON file")
    show.add_argument("-o", "--output", metavar="PNG", help="draw the map into this PNG file")
    show.add_argument(
        "--json",
        action="store_true",
        help="print the map's summary as JSON and nothing else on stdout (the text goes to stderr)",
    )
    show.set_defaults(run=run_show)


def _size(m: Map) -> str:
    xmin, ymin, xmax, ymax = m.bounds
    return f"{xmax - xmin:g} x {ymax - ymin:g} m"


def _bounds(geometry) -> list[float]:
    return [round(float(v), 6) for v in geometry.bounds]


def run_list(args) -> int:
    rows = []
    for name in list_maps():
        m = load_map(name)
        rows.append((name, _size(m), ", ".join(m.regions) or "-", m.description))
    widths = [max(len(row[k]) for row in rows) for k in range(3)]
    for row in rows:
        print("  ".join(cell.ljust(w) for cell, w in zip(row, widths)) + "  " + row[3])
    return 0


def summary(m: Map) -> dict:
    """What ``maps show --json`` prints: bounds and regions in map metres."""
    lat, lon = m.origin
    return {
        "name": m.name,
        "description": m.description,
        "origin": {"lat": lat, "lon": lon},
        "bounds": _bounds(m.area),
        "area_speed": m.area_speed,
        "regions": {
            r.name: {
                "role": r.role,
                "team": r.team,
                "bounds": _bounds(r.geometry),
                "area_m2": round(r.geometry.area, 3),
            }
            for r in m.regions.values()
        },
        "obstacles": len(m.obstacles),
        "zones": [{"name": z.name, "speed": z.speed, "area_m2": round(z.geometry.area, 3)} for z in m.zones],
    }


def run_show(args) -> int:
    out = Output(args.json)
    m = load_map(args.map)
    if args.output:
        out.figure(_draw(m), args.output, dpi=150)
    elif not args.json:
        lat, lon = m.origin
        out.say(f"{m.name}: {m.description}")
        out.say(f"  size      {_size(m)}, origin lat {lat:.6f} lon {lon:.6f}")
        out.say(f"  obstacles {len(m.obstacles)}, zones {len(m.zones)}, area speed {m.area_speed:g}")
        for r in m.regions.values():
            team = f", team {r.team}" if r.team else ""
            out.say(f"  region    {r.name} ({r.role}{team}), {r.geometry.area:.1f} m^2")
    out.json(summary(m))
    return 0


def _draw(m: Map):
    # matplotlib costs a few tenths of a second to import; only drawing pays for it.
    # A bare Figure renders headless without touching pyplot's global backend.
    from matplotlib.figure import Figure

    from bearcat.maps.plot import draw_map

    xmin, ymin, xmax, ymax = m.bounds
    height = min(8.0, max(3.5, 7.0 * (ymax - ymin) / (xmax - xmin) + 1.2))
    fig = Figure(figsize=(8, height), layout="constrained")
    ax = fig.subplots()
    scale = draw_map(ax, m)
    if scale is not None and (m.zones or m.area_speed != 1):
        fig.colorbar(scale, ax=ax, label="speed factor", shrink=0.8)
    ax.set_title(f"{m.name}\n{m.description}", fontsize=10)
    return fig
