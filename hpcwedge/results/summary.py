"""The text of `hpcwedge show` (the JSON is Result.to_dict): a head line with the global
mu^c, one table row per run, its cones (2D) or sign patterns (3D) under it, and the timings.

Runs are numbered from 0, in the order of the JSON's "runs" list (increasing mu), as
`plot --run` and `export --run` take them and the figures' titles say. A run with at most
LIST_MAX cones or patterns lists every one; a larger one (every_item False) gives the first,
the one of least mu^c, the spread of their mu^c and the command that lists them all.
"""
from __future__ import annotations

from hpcwedge.results.record import Result

#: a run with more cones or patterns than this is summarised unless every item is asked for
LIST_MAX = 8
#: the table's columns after mu: (head, width)
COLUMNS = (("wedged", 8), ("trivial", 8), ("cones", 6), ("patterns", 9))
INDENT = " " * 9


def show_lines(res: Result, path: str, every_item: bool = False) -> list[str]:
    """The lines `hpcwedge show path` prints for the result `res` read from `path` (rays
    unread are fine: only their counts are used)."""
    mu_c = "null" if res.mu_c is None else f"{res.mu_c:.12g}"
    status = ", ".join(x for x in (res.mu_c_status, global_caveat(res)) if x)
    lines = [f"{res.scene.name}: dim {res.scene.dim}, m {res.m}, mu_c = {mu_c}" + (f" ({status})" if status else "")]
    # mu as given (shortest round-trip digits): runs 1e-11 apart stay apart
    w = max([8] + [len(repr(float(run.mu))) for run in res.runs])
    lines.append(f"{'run':>3} {'mu':>{w}} " + " ".join(f"{h:>{c}}" for h, c in COLUMNS))
    for i, run in enumerate(res.runs):
        cells = (run.n_wedged_rays, run.n_trivial_rays, run.n_cones, run.n_patterns)
        lines.append(f"{i:>3} {float(run.mu)!r:>{w}} " + " ".join(f"{'-' if v is None else v:>{c}}"
                                                                   for v, (_, c) in zip(cells, COLUMNS)))
        for what, items in (("cone", run.cones or []), ("pattern", run.patterns or [])):
            lines += _items(what, items, path, every_item)
    lines.append("timings: " + ", ".join(f"{k} {v:.3f} s" for k, v in res.timings.items()))
    return lines


def _items(what: str, items: list, path: str, every_item: bool) -> list[str]:
    """The lines of a run's cones or patterns: all of them, or (more than LIST_MAX and not
    every_item) the first, the least mu^c, their spread and how to list them all."""
    if every_item or len(items) <= LIST_MAX:
        return [_item_line(what, j, it) for j, it in enumerate(items)]
    out = [_item_line(what, 0, items[0]) + " (the first)"]
    listed = 1
    valued = [j for j, it in enumerate(items) if it.mu_c is not None]
    if valued:
        least = min(valued, key=lambda j: (items[j].mu_c, j))
        if least != 0:
            out.append(_item_line(what, least, items[least]) + " (the least mu_c)")
            listed += 1
        spread = (f"mu_c of the {len(items):,} {what}s: {items[least].mu_c:.12g} to "
                  f"{max(items[j].mu_c for j in valued):.12g}")
        if len(valued) < len(items):
            spread += f" ({len(items) - len(valued):,} without a value)"
        out.append(INDENT + spread)
    undecided = sum(bool(getattr(it, "undecided", False)) for it in items)
    if undecided:
        out.append(INDENT + f"{undecided:,} {what}(s) undecided")
    out.append(INDENT + f"{len(items) - listed:,} more not listed: hpcwedge show {path} --all")
    return out


def _item_line(what: str, j: int, item) -> str:
    """One cone's or pattern's line."""
    if what == "cone":
        return (f"{INDENT}cone {j}: {len(item.rays)} rays, zero_u {item.zero_u}, zero_r {item.zero_r}, "
                f"mu_c {mu_c_text(item)}")
    return f"{INDENT}pattern {j}: contact {item.contact}, mu_c {mu_c_text(item)}" + (
        " (undecided)" if item.undecided else "")


def global_caveat(res: Result) -> str:
    """What `show` adds to the global mu^c when it is not certified to 1e-9: the listed value
    it is is not polished, or the global search left values unpolished or patterns' mu^c
    undecided (stats.bnb.unsettled; a file without it: any solve undecided)."""
    if res.mu_c is None:
        return ""
    items = [it for run in res.runs for it in (run.cones or []) + (run.patterns or [])]
    source = [it for it in items if it.mu_c == res.mu_c]
    if source:
        return "" if all(it.mu_c_polished is not False for it in source) else "not polished: an upper bound"
    st = res.stats
    bnb, unpolished = st.get("bnb") or {}, st.get("mu_c_unpolished", 0)
    if "unsettled" in bnb:
        doubt, what = bnb["unsettled"], "pattern(s) with mu^c undecided"
    else:
        doubt, what = bnb.get("undecided", 0), "solve(s) undecided"
    return f"not certified to 1e-9: {unpolished} value(s) not polished, {doubt} {what}" if unpolished or doubt else ""


def mu_c_text(item) -> str:
    """A cone's or pattern's mu^c for `show`: "-" when not computed; a value not certified
    to 1e-9 (an upper bound: a bisection bracket's end, or a 3D point not polished) says so."""
    if item.mu_c is None:
        return "-"
    return f"{item.mu_c:.12g}" + (" (not polished: an upper bound)" if item.mu_c_polished is False else "")
