"""Section of a grid store (scene kind "grid"): provenance, status and error estimates, the
reductions' grid and polished optima, maps of the stored quantities and of the reductions, the
stored u(tau) and the motions of the optima (recomputed with the solver).
"""

from __future__ import annotations

import numpy as np

from ._labels import format_value, param_label, quantity_label
from ._motion import animation_figure, compute_motion, motion_figure, params_text
from ._panels import full_data_note, quantity_maps, reduction_arrays, reduction_figures, series_figure
from ._read import SceneStore
from ._site import esc, fmt, provenance_table, scroll_table

__all__ = ["grid_section", "chosen_optima", "MAX_MOTIONS"]

#: Motions drawn per view (one per reduction, best cell), the first also animated.
MAX_MOTIONS = 2


def grid_section(site, sd: SceneStore, anchor: str) -> str:
    """The HTML of one grid store's view: title (h3 with id ``anchor``), then its parts (h4)."""
    parts = [f"<h3 id='{anchor}'>{esc(sd.name)}: {esc(sd.title)}</h3>"]
    # Every array this view draws, each read whole in one go (the store is opened lazily).
    sd.load(["status", *sd.quantities, "error_estimate", "series_u", "series_tau", "series_status",
             *(f"series_{d}" for d in sd.dims),
             *(n for red in sd.reductions for roles in reduction_arrays(sd, red).values() for n in roles.values())])
    if not sd.complete:
        parts.append("<p class='warn'>This store is incomplete (run interrupted or still running): "
                     f"state {esc(sd.state)}. Points not computed yet are blank.</p>")
    parts.append(site.guarded(f"{sd.name} provenance", lambda: _provenance_html(sd)))
    parts.append(site.guarded(f"{sd.name} status", lambda: _status_html(sd)))
    for red in sd.reductions:
        parts.append(site.guarded(f"{sd.name} {red['name']} table", lambda red=red: _reduction_table(sd, red)))
    names = [q for q in sd.quantities if q in sd.ds] + [d for d in ("error_estimate",) if d in sd.ds]
    if names:
        parts.append("<h4>Maps of the stored quantities</h4>")
    for q in names:
        parts.append(site.guarded(f"{sd.name} map {q}", lambda q=q: _with_data(site, sd, quantity_maps(sd, q), [q])))
    for red in sd.reductions:
        parts.append(f"<h4>Reduction <code>{esc(red['name'])}</code>: {esc(red.get('statistic', 'max'))} of "
                     f"{quantity_label(red['quantity'], sd.p)} over "
                     f"{', '.join(param_label(a, sd.p) for a in red.get('over', []))}</h4>")
        parts.append(site.guarded(f"{sd.name} reduction {red['name']}",
                                  lambda red=red: _with_data(site, sd, reduction_figures(sd, red),
                                                             [n for roles in reduction_arrays(sd, red).values()
                                                              for n in roles.values()])))
    if "series_u" in sd.ds:
        parts.append("<h4>Stored velocity series</h4>")
        parts.append(site.guarded(f"{sd.name} series", lambda: site.maybe_figure(series_figure(sd))))
    parts.append(site.guarded(f"{sd.name} motions", lambda: _motions(site, sd)))
    return "\n".join(parts)


def _with_data(site, sd: SceneStore, figs, names) -> str:
    """The figure(s) ``figs`` (one, a list, or None), then where their full data is."""
    figs = [f for f in (figs if isinstance(figs, list) else [figs]) if f is not None]
    if not figs:
        return ""
    return "".join(site.figure(f) for f in figs) + full_data_note(sd, names)


def _motions(site, sd: SceneStore) -> str:
    optima = chosen_optima(sd)[:MAX_MOTIONS]
    if not optima:
        return ""
    out = ["<h4>Motions of the optima</h4>",
           "<p class='note'>Recomputed with the solver (<code>solve_periodic(..., return_series=True)</code>, "
           f"rtol {sd.rtol:g}) at the best cell of each reduction. Top: the body at eight instants of one "
           "period, side by side, with the horizontal force per unit length along each link (arrows, "
           "longest = 0.2 body lengths); bottom: u(τ) (dotted: its mean T U), φ(τ), and the positions of the "
           "centre of mass, apex and link tips over three periods.</p>"]
    for k, (label, params, value_text) in enumerate(optima):
        def one(label=label, params=params, value_text=value_text, k=k):
            m = compute_motion(sd.family, params, rtol=sd.rtol, method=sd.method, label=label,
                               value_text=value_text)
            head = (f"<h5>{esc(label)}</h5><p>{value_text}; {params_text(params, sd.p)}; "
                    f"T U = {m.displacement:.4g} body lengths per period; solver error estimate "
                    f"{m.error_estimate:.2g}</p>")
            html_ = head + site.figure(motion_figure(m, sd.p))
            if k == 0:
                html_ += "<h5>Animation</h5>" + site.figure(animation_figure(m, sd.p))
            return html_
        out.append(site.guarded(f"{sd.name} motion {label}", one))
    return "\n".join(out)


# ---------------------------------------------------------------------------
# Tables
# ---------------------------------------------------------------------------


def _provenance_html(sd: SceneStore) -> str:
    shape = sd.meta.get("layout", {}).get("shape", [])
    n = int(np.prod(shape)) if shape else 0
    dims = " × ".join(f"{param_label(d, sd.p)} ({s})" for d, s in zip(sd.dims, shape))
    fixed = ", ".join(f"{param_label(k, sd.p)} = {format_value(k, v)}" for k, v in sd.fixed.items())
    return provenance_table(sd, [
        ("grid", f"{dims} = {n:,} points"),
        ("fixed", fixed or "—"),
        ("solver", f"{esc(sd.method)}, rtol {sd.rtol:g}"),
    ])


def _status_html(sd: SceneStore) -> str:
    if "status" not in sd.ds:
        return "<p class='warn'>no status array in this store</p>"
    st = np.asarray(sd.ds["status"].values)
    meanings = sd.ds["status"].attrs.get("flag_meanings", {})
    codes, counts = np.unique(st, return_counts=True)
    n = st.size
    rows = "".join(f"<tr><td class='num'>{int(c)}</td><td class='num'>{int(k):,}</td>"
                   f"<td class='num'>{100 * k / n:.2f} %</td><td>{esc(meanings.get(str(int(c)), '?'))}</td></tr>"
                   for c, k in zip(codes, counts))
    failed = int(np.count_nonzero(st > 0))
    computed = int(np.count_nonzero(st >= 0))
    out = [f"<h4>Points, failures and error estimates</h4><p>{n:,} points; {computed:,} computed; "
           f"<b>{failed:,} failures</b>" + (f" ({100 * failed / max(computed, 1):.2f} % of computed)" if computed else "")
           + "</p>", scroll_table(f"<table><tr><th>status</th><th>points</th><th>share</th><th>reason</th></tr>{rows}</table>")]
    if failed:
        idx = np.argwhere(st > 0)[:12]
        head = "".join(f"<th>{param_label(d, sd.p)}</th>" for d in sd.ds["status"].dims)
        body = ""
        for ix in idx:
            vals = "".join(f"<td class='num'>{format_value(d, float(sd.ds[d].values[i]))}</td>"
                           for d, i in zip(sd.ds["status"].dims, ix))
            code = int(st[tuple(ix)])
            body += f"<tr>{vals}<td>{code}: {esc(meanings.get(str(code), '?'))}</td></tr>"
        out.append(f"<details><summary>first {len(idx)} failed points</summary>"
                   + scroll_table(f"<table><tr>{head}<th>reason</th></tr>{body}</table>") + "</details>")
    ok = st == 0
    if "error_estimate" in sd.ds and ok.any():
        e = np.asarray(sd.ds["error_estimate"].values)[ok]
        e = e[np.isfinite(e)]
        if e.size:
            q50, q95 = np.percentile(e, [50, 95])
            out.append(f"<p>Solver error estimate over the {e.size:,} converged points: median {q50:.2g}, "
                       f"95th percentile {q95:.2g}, max {e.max():.2g} (rtol {sd.rtol:g}; "
                       f"{int(np.count_nonzero(e > sd.rtol))} above rtol).</p>")
    else:
        out.append(f"<p class='note'>Error estimates are not stored for this scene; every converged point "
                   f"(status 0) has its solver error estimate below rtol = {sd.rtol:g}.</p>")
    return "".join(out)


def _reduction_table(sd: SceneStore, red: dict) -> str:
    """Grid and polished maxima side by side, per kept cell (or a summary when there are many)."""
    arrays = reduction_arrays(sd, red)
    if "grid" not in arrays:
        return ""
    g = sd.ds[arrays["grid"]["value"]]
    dims = list(g.dims)
    gv = np.asarray(g.values, dtype=np.float64)
    label = f"{red['name']}: {red.get('statistic', 'max')} of {quantity_label(red['quantity'], sd.p)}"
    pol = arrays.get("polished")
    if pol is None:
        finite = gv[np.isfinite(gv)]
        best = f"{np.max(finite):.5g}" if finite.size else "n/a"
        return (f"<p>Reduction <code>{esc(red['name'])}</code>: grid maxima only (not polished); best "
                f"{best} over {gv.size} cells ({int(np.count_nonzero(~np.isfinite(gv)))} without a valid point).</p>")
    pv = np.asarray(sd.ds[pol["value"]].transpose(*dims).values, dtype=np.float64)
    pst = np.asarray(sd.ds[pol["status"]].transpose(*dims).values) if "status" in pol else np.zeros(gv.shape, int)
    pev = np.asarray(sd.ds[pol["evaluations"]].transpose(*dims).values) if "evaluations" in pol else None
    with np.errstate(divide="ignore", invalid="ignore"):
        gain = (pv - gv) / np.abs(gv)
    fin = np.isfinite(gain)
    record = _polish_record(sd, red, dims, gv.shape)
    summary = (f"<p>Reduction <code>{esc(red['name'])}</code> ({label}): {gv.size} cells; polishing changed the "
               f"maximum by median {np.median(gain[fin]) * 100 if fin.any() else float('nan'):.3g} %, "
               f"at most {np.max(gain[fin]) * 100 if fin.any() else float('nan'):.3g} %; "
               + (record["summary"] if record else f"{int(np.count_nonzero(pst > 0))} polished optima failed; ")
               + f"{int(pev.sum()) if pev is not None else '?'} solver calls spent polishing.</p>")
    head = "".join(f"<th>{param_label(d, sd.p)}</th>" for d in dims)
    over = [a for a in red.get("over", []) if a in arrays["grid"]]
    head += "<th>grid max</th><th>polished max</th><th>change</th>"
    head += "".join(f"<th>grid / polished {param_label(a, sd.p)}</th>" for a in over) + "<th>polish status</th>"
    if record:
        head += "<th>uncertainty (relative)</th><th>on the domain's edge</th>"
    rows = []
    for ix in np.ndindex(*gv.shape):
        if len(rows) >= 60:
            break
        cells = "".join(f"<td class='num'>{format_value(d, float(sd.ds[d].values[i]))}</td>" for d, i in zip(dims, ix))
        cells += f"<td class='num'>{fmt(gv[ix], 5)}</td><td class='num'>{fmt(pv[ix], 5)}</td>"
        cells += f"<td class='num'>{fmt(gain[ix] * 100, 3)} %</td>"
        for a in over:
            ga = float(sd.ds[arrays['grid'][a]].transpose(*dims).values[ix])
            pa = float(sd.ds[pol[a]].transpose(*dims).values[ix]) if a in pol else float("nan")
            cells += f"<td class='num'>{format_value(a, ga)} / {format_value(a, pa)}</td>"
        if record:
            cells += f"<td>{esc(record['status_words'].get(str(int(pst[ix])), str(int(pst[ix]))))}</td>"
            cells += f"<td class='num'>{fmt(record['uncertainty'][ix], 2)}</td><td>{esc(record['edge_text'](ix))}</td>"
        else:
            cells += f"<td class='num'>{int(pst[ix])}</td>"
        rows.append(f"<tr>{cells}</tr>")
    more = f" (first {len(rows)} of {gv.size})" if len(rows) < gv.size else ""
    return (summary + f"<details><summary>grid and polished maxima side by side{more}</summary>"
            + scroll_table(f"<table><tr>{head}</tr>{''.join(rows)}</table>") + "</details>")


#: words of the polish statuses (pipeline.polish.record.STATUS_MEANINGS), short for a table
_POLISH_STATUS = {"-1": "not computed", "0": "converged", "1": "cap reached (not converged)", "2": "failed"}


def _polish_record(sd: SceneStore, red: dict, dims: list, shape: tuple) -> dict | None:
    """The polish record of reduction ``red`` (issue 44: status, uncertainty, edges), or None
    for a store written before it: a summary sentence, per-cell uncertainty and edge text."""
    base = f"{red['name']}_polished"
    if f"{base}_uncertainty" not in sd.ds:
        return None
    st = np.asarray(sd.ds[f"{base}_status"].transpose(*dims).values).astype(int)
    unc = np.asarray(sd.ds[f"{base}_uncertainty"].transpose(*dims).values, dtype=np.float64)
    edges = {a: np.asarray(sd.ds[f"{base}_{a}_edge"].transpose(*dims).values).astype(int)
             for a in red.get("over", []) if f"{base}_{a}_edge" in sd.ds}
    counts = {k: int(np.count_nonzero(st == int(k))) for k in _POLISH_STATUS}
    words = ", ".join(f"{n} {_POLISH_STATUS[k]}" for k, n in counts.items() if n)
    fu = unc[np.isfinite(unc)]
    on_edge = [f"{param_label(a, sd.p)} at its lower end in {int(np.count_nonzero(e < 0))} cells, upper end in "
               f"{int(np.count_nonzero(e > 0))}" for a, e in edges.items() if np.any(e != 0)]
    summary = (f"polish status: {words}; relative uncertainty median {np.median(fu):.2g}, at most "
               f"{np.max(fu):.2g}; " if fu.size else f"polish status: {words}; ")
    summary += ("arg-max on the polish domain's edge: " + "; ".join(on_edge) + "; ") if on_edge else \
        "no arg-max on the polish domain's edge; "

    def edge_text(ix) -> str:
        out = [f"{param_label(a, sd.p)} {'lower' if e[ix] < 0 else 'upper'}" for a, e in edges.items() if e[ix] != 0]
        return ", ".join(out) or "interior"

    return {"summary": summary, "uncertainty": unc, "status_words": _POLISH_STATUS, "edge_text": edge_text}


# ---------------------------------------------------------------------------
# Choice of optima for the motions
# ---------------------------------------------------------------------------


def chosen_optima(sd: SceneStore) -> list[tuple[str, dict, str]]:
    """(label, every scene parameter, value text) of the best cell of each reduction, efficiency first.

    The polished optimum is used where it exists and is finite, else the grid optimum; the
    stored series points stand in when the scene has no reduction.
    """
    out = []
    reds = sorted(sd.reductions, key=lambda r: 0 if "efficiency" in r.get("quantity", "") else 1)
    for red in reds:
        arrays = reduction_arrays(sd, red)
        for kind in ("polished", "grid"):
            roles = arrays.get(kind)
            if roles is None:
                continue
            da = sd.ds[roles["value"]]
            v = np.asarray(da.values, dtype=np.float64)
            if red.get("statistic") == "min":
                v = -v
            if not np.isfinite(v).any():
                continue
            ix = np.unravel_index(int(np.nanargmax(v)), v.shape)
            params = dict(sd.fixed)
            for d, i in zip(da.dims, ix):
                if d in sd.dims:
                    params[d] = float(sd.ds[d].values[i])
            for a in red.get("over", []):
                if a in roles:
                    params[a] = float(np.asarray(sd.ds[roles[a]].values)[ix])
            if any(d not in params or not np.isfinite(params[d]) for d in sd.dims):
                continue
            val = float(np.asarray(sd.ds[roles.get('signed', roles['value'])].values)[ix])
            text = f"{kind} optimum of <code>{esc(red['name'])}</code>: {quantity_label(red['quantity'], sd.p)} = {val:.5g}"
            out.append((f"best {red['name']} ({kind})", params, text))
            break
    if not out and "series_u" in sd.ds:
        for i in range(sd.ds.sizes["series_point"]):
            params = dict(sd.fixed)
            params.update({d: float(sd.ds[f"series_{d}"].values[i]) for d in sd.dims})
            out.append((f"series point {i}", params, f"stored series point {i}"))
    return out
