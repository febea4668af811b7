"""Report sections of the study scenes (``pipeline.kind`` accuracy | stiffness).

* accuracy: the reference and its cross-check, work-precision panels (error in U and in P
  against wall time per solve, log-log, one panel per case) for each method's tolerances and
  fixed grids and the scipy LSODA baseline, with the observed order printed at each curve;
* stiffness: status counts, maps (motion x swept value) of status, true error / rtol and time
  per method and rtol, U and P against delta;
* both: honest tolerances, the share of converged solves whose true error is within rtol and
  within 10 rtol, and the table of exceptions; over every study store together as well.

The reductions here are plain numpy over the stored arrays (tested against brute force in
``tests/test_study.py``).
"""

from __future__ import annotations

import math

import numpy as np

from ._figure import subplots
from ._site import esc, fmt, provenance_table, scroll_table

__all__ = ["study_section", "combined_honesty", "honesty_records", "honesty_summary", "fitted_order",
           "honesty_section", "REFERENCE_SHARE"]

#: A reference is trusted for a solve at ``rtol`` when its cross-check difference is at most
#: this share of rtol; other solves are counted apart ("reference unverified"), not judged.
REFERENCE_SHARE = 0.1
_COLORS = {"periodic": "#1f77b4", "march": "#d62728", "baseline": "#2ca02c"}
#: one colour per solver status code 0 .. 8 (``solver.STATUS_REASONS``)
STATUS_COLORS = ["#2ca02c", "#9467bd", "#ff7f0e", "#8c564b", "#d62728", "#e377c2", "#bcbd22", "#7f7f7f",
                 "#17becf"]


def _labels(sd, name) -> list[str]:
    return list(sd.ds[name].attrs.get("labels", []))


def _v(sd, name) -> np.ndarray:
    return sd.array(name)


def _scan_names(sd) -> tuple[str, str]:
    """The names of a stiffness store's scan index and value: ("scan", "scan_value"), or
    ("sweep", "sweep_value") in a store written before issue 37 renamed them."""
    return ("scan", "scan_value") if "scan" in sd.ds else ("sweep", "sweep_value")


# ---------------------------------------------------------------------------
# Reductions
# ---------------------------------------------------------------------------


def fitted_order(x, error, floor=0.0) -> float:
    """Observed order: minus the least-squares slope of log(error) on log(x).

    Only points with finite error above ``floor`` (the reference's own uncertainty) count;
    NaN with fewer than 3 such points.
    """
    x, e = np.asarray(x, float), np.asarray(error, float)
    ok = np.isfinite(x) & np.isfinite(e) & (e > max(floor, 1e-300)) & (x > 0)
    if np.count_nonzero(ok) < 3:
        return math.nan
    slope = np.polyfit(np.log(x[ok]), np.log(e[ok]), 1)[0]
    return float(-slope)


def point_label(sd, i: int) -> str:
    """'motion' or 'motion, parameter = value' of point ``i``."""
    motion = _labels(sd, "motion")[int(_v(sd, "motion")[i])]
    scan, scan_value = _scan_names(sd)
    j = int(_v(sd, scan)[i])
    if j < 0:
        return motion
    return f"{motion}, {_labels(sd, scan)[j]} = {float(_v(sd, scan_value)[i]):.4g}"


def honesty_records(sd) -> list[dict]:
    """One record per (point, method, rtol) solve: status, estimate, true error, reference check."""
    st, est, te = _v(sd, "status"), _v(sd, "error_estimate"), _v(sd, "true_error")
    ref_ok, check = _v(sd, "ref_status") == 0, _v(sd, "check_difference")
    methods, rtols = _labels(sd, "method"), _v(sd, "rtol")
    out = []
    for i, a, b in np.ndindex(*st.shape):
        rtol = float(rtols[b])
        trusted = bool(ref_ok[i] and np.isfinite(check[i]) and check[i] <= REFERENCE_SHARE * rtol)
        out.append({"scene": sd.name, "point": i, "label": point_label(sd, i), "method": methods[a], "rtol": rtol,
                    "status": int(st[i, a, b]), "estimate": float(est[i, a, b]), "true_error": float(te[i, a, b]),
                    "check_difference": float(check[i]), "trusted": trusted,
                    "ratio": float(te[i, a, b]) / rtol})
    return out


def honesty_summary(records) -> dict:
    """Counts over converged solves with a trusted reference: within rtol, within 10 rtol."""
    judged = [r for r in records if r["status"] == 0 and r["trusted"] and np.isfinite(r["true_error"])]
    n = len(judged)
    within = sum(r["ratio"] <= 1 for r in judged)
    within10 = sum(r["ratio"] <= 10 for r in judged)
    return {"solves": len(records), "converged": sum(r["status"] == 0 for r in records), "judged": n,
            "unverified": sum(r["status"] == 0 and not r["trusted"] for r in records),
            "within": within, "within10": within10,
            "fraction_within": within / n if n else math.nan, "fraction_within10": within10 / n if n else math.nan,
            "exceptions": sorted((r for r in judged if r["ratio"] > 1), key=lambda r: -r["ratio"])}


def _fmt(x, d=3) -> str:
    return fmt(x, d)


def honesty_section(records, title="Honest tolerances", level: int = 4) -> str:
    s = honesty_summary(records)
    fw, f10 = s["fraction_within"], s["fraction_within10"]
    verdict = ("meets" if (fw >= 0.99 and f10 == 1.0) else "misses") if s["judged"] else "cannot judge"
    rows = "".join(
        f"<tr><td>{esc(r['scene'])}</td><td>{esc(r['label'])}</td><td>{esc(r['method'])}</td>"
        f"<td class='num'>{r['rtol']:.0e}</td><td class='num'>{_fmt(r['estimate'])}</td>"
        f"<td class='num'>{_fmt(r['true_error'])}</td><td class='num'><b>{_fmt(r['ratio'])}</b></td>"
        f"<td class='num'>{_fmt(r['check_difference'])}</td></tr>" for r in s["exceptions"])
    table = (scroll_table(f"<table><tr><th>scene</th><th>point</th><th>method</th><th>rtol</th><th>estimate</th>"
                          f"<th>true error</th><th>true error / rtol</th><th>reference check</th></tr>{rows}</table>")
             if rows else "<p>No exceptions: every judged solve is within its rtol.</p>")
    unverified = sorted({(r["scene"], r["label"], r["check_difference"]) for r in records
                         if r["status"] == 0 and not r["trusted"]})
    if unverified:
        items = "".join(f"<li>{esc(sc)}: {esc(lb)} (cross-check difference {_fmt(d)})</li>"
                        for sc, lb, d in unverified)
        table += ("<details><summary>Points whose reference is not verified finely enough</summary>"
                  f"<ul>{items}</ul></details>")
    return (f"<h{level}>{esc(title)}</h{level}><p>Of {s['solves']} solves, {s['converged']} converged; "
            f"{s['judged']} of these are judged against a reference whose cross-check difference is at most "
            f"{REFERENCE_SHARE:g} rtol ({s['unverified']} converged solves have a reference not verified that "
            f"finely and are not judged). True error within rtol: <b>{s['within']}/{s['judged']} = "
            f"{100 * fw:.1f} %</b> (target ≥ 99 %); within 10 rtol: <b>{s['within10']}/{s['judged']} = "
            f"{100 * f10:.1f} %</b> (target 100 %): the scene <b>{verdict}</b> the targets.</p>"
            f"<p>Exceptions (true error above rtol although the solver reported convergence):</p>{table}")


# ---------------------------------------------------------------------------
# Common tables
# ---------------------------------------------------------------------------


def _reference_table(sd) -> str:
    check_labels = _labels(sd, "check_method")
    rows = []
    for i in range(sd.ds.sizes["point"]):
        cm = int(_v(sd, "check_method")[i])
        rows.append(f"<tr><td>{esc(point_label(sd, i))}</td><td class='num'>{_fmt(_v(sd, 'U_ref')[i], 8)}</td>"
                    f"<td class='num'>{_fmt(_v(sd, 'P_ref')[i], 8)}</td><td class='num'>{int(_v(sd, 'ref_status')[i])}"
                    f"</td><td class='num'>{int(_v(sd, 'ref_n_tau')[i])}</td>"
                    f"<td>{esc(check_labels[cm] if 0 <= cm < len(check_labels) else '—')}</td>"
                    f"<td class='num'>{_fmt(_v(sd, 'check_difference')[i])}</td></tr>")
    ref = sd.science.get("reference", {})
    return (f"<details><summary>Reference solutions ({len(rows)} points): periodic at rtol {ref.get('rtol', 0):.0e}, "
            f"cross-checked by {esc(ref.get('check'))} (check rtol {ref.get('check_rtol', 0):.0e}, fixed grid "
            f"{ref.get('check_steps')} steps)</summary>"
            + scroll_table("<table><tr><th>point</th><th>U_ref</th><th>P_ref</th><th>status</th><th>n_tau</th>"
                           f"<th>cross-check</th><th>difference</th></tr>{''.join(rows)}</table>")
            + "</details>")


def _timing_note(sd) -> str:
    run = sd.meta.get("run", {})
    return (f"<p class='note'>Times are the wall time of one single-point solve measured inside the task "
            f"(<code>time.perf_counter</code>, after numba warm-up, one numba thread, the fastest of up to 3 "
            f"calls within 0.5 s) on a machine shared with other work "
            f"({run.get('workers', '?')} workers); the whole run took {run.get('wall_seconds', float('nan')):.1f} s "
            f"wall. Errors are in the solver's norm: U relative to max(|U T|, 1e-3 V), P relative.</p>")


def _status_table(sd) -> str:
    st = _v(sd, "status")
    meanings = sd.ds["status"].attrs.get("flag_meanings", {})
    methods, rtols = _labels(sd, "method"), _v(sd, "rtol")
    head = "".join(f"<th>{esc(m)} rtol {r:.0e}</th>" for m in methods for r in rtols)
    rows = ""
    for code in np.unique(st):
        cells = "".join(f"<td class='num'>{int(np.count_nonzero(st[:, a, b] == code))}</td>"
                        for a in range(len(methods)) for b in range(len(rtols)))
        rows += f"<tr><td>{int(code)}: {esc(meanings.get(str(int(code)), '?'))}</td>{cells}</tr>"
    return scroll_table(f"<table><tr><th>status</th>{head}</tr>{rows}</table>")


# ---------------------------------------------------------------------------
# Accuracy
# ---------------------------------------------------------------------------


def _curve(fig, row, col, x, y, name, color, dash, order_text, hover, show):
    ok = np.isfinite(x) & np.isfinite(y) & (y > 0)
    if not ok.any():
        return
    x, y, hover = np.asarray(x)[ok], np.asarray(y)[ok], [h for h, k in zip(hover, ok) if k]
    text = [""] * (len(x) - 1) + [order_text]
    fig.add_trace(dict(type="scatter", x=x, y=y, mode="lines+markers+text", name=name, legendgroup=name,
                       showlegend=show, line={"color": color, "dash": dash}, marker={"size": 6}, text=text,
                       textposition="middle right", textfont={"size": 10, "color": color},
                       hovertext=hover, hoverinfo="text"), row=row, col=col)


def accuracy_orders(sd, quantity: str) -> dict:
    """Observed orders per (point, method): fixed grids (error vs N) and adaptive (error vs time),
    and the baseline's (error vs time); ``quantity`` "U" or "P"."""
    methods = _labels(sd, "method")
    floor = _v(sd, "check_difference")
    out = {}
    for i in range(sd.ds.sizes["point"]):
        for a, m in enumerate(methods):
            fixed = (fitted_order(_v(sd, "n_steps"), _v(sd, f"fixed_error_{quantity}")[i, a], floor[i])
                     if "n_steps" in sd.ds else math.nan)
            adaptive = fitted_order(_v(sd, "seconds")[i, a], _v(sd, f"error_{quantity}")[i, a], floor[i])
            per_step = fitted_order(_v(sd, "n_tau")[i, a], _v(sd, f"error_{quantity}")[i, a], floor[i])
            out[i, m] = (fixed, adaptive, per_step)
        if "baseline_tol" in sd.ds:
            out[i, "baseline"] = (math.nan, fitted_order(_v(sd, "baseline_seconds")[i],
                                                         _v(sd, f"baseline_error_{quantity}")[i], floor[i]), math.nan)
    return out


def work_precision_figure(sd, quantity: str):
    """Error in ``quantity`` (U or P) against seconds per solve, one panel per case."""
    n = sd.ds.sizes["point"]
    cols = 3
    rows = -(-n // cols)
    names = [point_label(sd, i) for i in range(n)]
    fig = subplots(rows=rows, cols=cols, subplot_titles=names, horizontal_spacing=0.07,
                   vertical_spacing=0.3 / rows)
    methods, rtols = _labels(sd, "method"), _v(sd, "rtol")
    orders = accuracy_orders(sd, quantity)
    for i in range(n):
        r, c = i // cols + 1, i % cols + 1
        for a, m in enumerate(methods):
            fixed_order, _, step_order = orders[i, m]
            _curve(fig, r, c, _v(sd, "seconds")[i, a], _v(sd, f"error_{quantity}")[i, a], f"{m} (rtol; order vs n_tau)",
                   _COLORS[m], "solid", f"{step_order:.1f}",
                   [f"{m} rtol {t:.0e}: status {s}, estimate {e:.2g}" for t, s, e in
                    zip(rtols, _v(sd, "status")[i, a], _v(sd, "error_estimate")[i, a])], i == 0)
            if "n_steps" in sd.ds:
                _curve(fig, r, c, _v(sd, "fixed_seconds")[i, a], _v(sd, f"fixed_error_{quantity}")[i, a],
                       f"{m} (fixed N)", _COLORS[m], "dot", f"N^-{fixed_order:.1f}",
                       [f"{m} N = {k}: status {s}" for k, s in zip(_v(sd, "n_steps"), _v(sd, "fixed_status")[i, a])],
                       i == 0)
        if "baseline_tol" in sd.ds:
            _curve(fig, r, c, _v(sd, "baseline_seconds")[i], _v(sd, f"baseline_error_{quantity}")[i],
                   "scipy LSODA baseline", _COLORS["baseline"], "dash", f"{orders[i, 'baseline'][1]:.1f}",
                   [f"LSODA rtol {t:.0e}: status {s}, {k} periods" for t, s, k in
                    zip(_v(sd, "baseline_tol"), _v(sd, "baseline_status")[i], _v(sd, "baseline_periods")[i])],
                   i == 0)
    fig.update_xaxes(type="log", title_text="seconds per solve", title_font={"size": 10})
    fig.update_yaxes(type="log", title_text=f"error in {quantity}", title_font={"size": 10}, exponentformat="power")
    fig.update_layout(height=300 * rows + 80, title={"text": f"Work-precision: error in {quantity} (solver norm) "
                                                             "against wall time per solve; number at each curve: "
                                                             "observed order", "font": {"size": 14}},
                      legend={"orientation": "h", "y": -0.05}, margin={"t": 80, "l": 60, "r": 60, "b": 60})
    fig.update_annotations(font_size=11)
    return fig


def _order_table(sd) -> str:
    methods = _labels(sd, "method")
    ou, op = accuracy_orders(sd, "U"), accuracy_orders(sd, "P")
    cols = [m for m in methods] + (["baseline"] if "baseline_tol" in sd.ds else [])
    head = "".join(f"<th>{esc(m)}: N-slope U / P</th><th>{esc(m)}: n_tau-slope U / P</th>"
                   f"<th>{esc(m)}: time-slope U / P</th>" for m in cols)
    rows = ""
    for i in range(sd.ds.sizes["point"]):
        cells = "".join(f"<td class='num'>{_fmt(ou[i, m][k], 2)} / {_fmt(op[i, m][k], 2)}</td>"
                        for m in cols for k in range(3))
        rows += f"<tr><td>{esc(point_label(sd, i))}</td>{cells}</tr>"
    return ("<p class='note'>Observed orders: N-slope = −d log(error)/d log N on the fixed uniform grids "
            "(<code>solve_fixed_grid</code>; printed at the dotted curves); n_tau-slope = the same against the "
            "final adaptive grid size over the tolerances (printed at the solid curves); time-slope = "
            "−d log(error)/d log(seconds) over the tolerances (a work-precision slope: higher is cheaper "
            "accuracy; noisy where a solve takes milliseconds). Least squares over the points above the "
            "reference's cross-check difference; n/a with fewer than 3.</p>"
            + scroll_table(f"<table><tr><th>case</th>{head}</tr>{rows}</table>"))


def _accuracy_body(site, sd) -> list[str]:
    parts = [_timing_note(sd), site.guarded(f"{sd.name} reference", lambda: _reference_table(sd)),
             "<h4>Status of the adaptive solves</h4>", site.guarded(f"{sd.name} status", lambda: _status_table(sd))]
    if "baseline_tol" in sd.ds:
        parts.append("<p class='note'>The scipy baseline is <code>solver.tools.bench.baseline_point</code> (LSODA, "
                     "period by period from rest until periodic, serial, wall-time cap "
                     f"{sd.science.get('baseline', {}).get('cap_seconds')} s, phi from the solver's kinematics "
                     "kernel); a point that hits the cap has no baseline value.</p>")
    for q in ("U", "P"):
        parts.append(site.guarded(f"{sd.name} work-precision {q}",
                                  lambda q=q: site.figure(work_precision_figure(sd, q))))
    parts.append(site.guarded(f"{sd.name} orders", lambda: _order_table(sd)))
    return parts


# ---------------------------------------------------------------------------
# Stiffness
# ---------------------------------------------------------------------------


def _value_label(parameter: str, v: float) -> str:
    """Powers of two as 2^k for the friction parameters, else 3 significant digits."""
    k = math.log2(v) if v > 0 else math.nan
    if parameter in ("anisotropy_ratio", "scaled_period") and abs(k - round(k)) < 1e-9:
        return f"2^{int(round(k))}"
    return f"{v:.3g}"


def _scan_maps(sd, j: int):
    """Maps motion x scanned value of status, log10(true error / rtol) and log10(seconds)."""
    scan, scan_value = _scan_names(sd)
    idx = np.flatnonzero(_v(sd, scan) == j)
    motions_all = _labels(sd, "motion")
    motion_idx = sorted(set(int(m) for m in _v(sd, "motion")[idx]))
    xs = sorted(set(float(v) for v in _v(sd, scan_value)[idx]))
    methods, rtols = _labels(sd, "method"), _v(sd, "rtol")
    meanings = sd.ds["status"].attrs.get("flag_meanings", {})
    parameter = _labels(sd, scan)[j]
    row_names = [f"{m}, rtol {r:.0e}" for m in methods for r in rtols]
    titles = [f"{rn}: {what}" for rn in row_names for what in ("status", "log10(true error / rtol)",
                                                                "log10(seconds)")]
    fig = subplots(rows=len(row_names), cols=3, subplot_titles=titles, horizontal_spacing=0.08,
                   vertical_spacing=0.25 / len(row_names))
    xlab = [_value_label(parameter, v) for v in xs]
    ylab = [motions_all[m] for m in motion_idx]
    n_codes = len(STATUS_COLORS)
    status_scale = [[k / (n_codes - 1), c] for k, c in enumerate(STATUS_COLORS)]
    used = _v(sd, "used_method") if "used_method" in sd.ds else None
    for a, m in enumerate(methods):
        for b, r in enumerate(rtols):
            row = a * len(rtols) + b + 1
            grids = {k: np.full((len(ylab), len(xlab)), np.nan) for k in ("status", "ratio", "time")}
            hover = [[""] * len(xlab) for _ in ylab]
            for i in idx:
                y, x = motion_idx.index(int(_v(sd, "motion")[i])), xs.index(float(_v(sd, scan_value)[i]))
                code = int(_v(sd, "status")[i, a, b])
                te = float(_v(sd, "true_error")[i, a, b])
                grids["status"][y, x] = code
                grids["ratio"][y, x] = math.log10(te / r) if te > 0 else np.nan
                grids["time"][y, x] = math.log10(float(_v(sd, "seconds")[i, a, b]))
                kept = ""
                if used is not None and int(used[i, a, b]) not in (a, -1):
                    kept = f"<br>answer kept: {methods[int(used[i, a, b])]} (fallback)"
                hover[y][x] = (f"{ylab[y]}, {parameter} = {xlab[x]}<br>{m} rtol {r:.0e}: status {code} "
                               f"({meanings.get(str(code), '?')})<br>estimate {_fmt(_v(sd, 'error_estimate')[i, a, b])}"
                               f", true error {_fmt(te)}<br>{int(_v(sd, 'iterations')[i, a, b])} iterations, n_tau "
                               f"{int(_v(sd, 'n_tau')[i, a, b])}, {_v(sd, 'seconds')[i, a, b]:.3g} s<br>U "
                               f"{_fmt(_v(sd, 'U')[i, a, b], 6)}, P {_fmt(_v(sd, 'P')[i, a, b], 6)}{kept}")
            for c, (k, scale, zmin, zmax, bar_x) in enumerate((
                    ("status", status_scale, 0, n_codes - 1, 0.285), ("ratio", "RdBu_r", -3, 3, 0.645),
                    ("time", "Viridis", -2, 1, 1.005)), start=1):
                fig.add_trace(dict(type="heatmap", z=grids[k], x=xlab, y=ylab, colorscale=scale, zmin=zmin,
                                   zmax=zmax, hovertext=hover, hoverinfo="text", xgap=1, ygap=1,
                                   showscale=row == 1, colorbar={"x": bar_x, "len": 0.9 / len(row_names),
                                                                 "y": 1.0, "yanchor": "top", "thickness": 8,
                                                                 "tickfont": {"size": 9}}),
                              row=row, col=c)
                if c > 1:
                    fig.update_yaxes(showticklabels=False, row=row, col=c)
    fig.update_xaxes(type="category", tickangle=0, tickfont={"size": 9})
    for c in (1, 2, 3):
        fig.update_xaxes(title_text=parameter, title_font={"size": 10}, row=len(row_names), col=c)
    fig.update_layout(height=260 * len(row_names) + 80, margin={"t": 80, "l": 130, "r": 40, "b": 40},
                      title={"text": f"Scan of {parameter}: status (0 green = converged), true error / rtol "
                                     "(red above rtol) and time per solve", "font": {"size": 14}})
    fig.update_annotations(font_size=10)
    return fig


def _delta_figure(sd):
    """U and P of the reference against delta for every motion of the delta scan."""
    scan = _scan_names(sd)[0]
    scans = _labels(sd, scan)
    if "delta" not in scans:
        return None
    idx = np.flatnonzero(_v(sd, scan) == scans.index("delta"))
    fig = subplots(rows=1, cols=2, subplot_titles=["U (reference)", "P (reference)"])
    motions = _labels(sd, "motion")
    for k, m in enumerate(sorted(set(int(x) for x in _v(sd, "motion")[idx]))):
        sel = idx[_v(sd, "motion")[idx] == m]
        sel = sel[np.argsort(_v(sd, "delta")[sel])]
        for col, q in ((1, "U_ref"), (2, "P_ref")):
            fig.add_trace(dict(type="scatter", x=_v(sd, "delta")[sel], y=_v(sd, q)[sel], mode="lines+markers",
                               name=motions[m], legendgroup=motions[m], showlegend=col == 1,
                               line={"color": STATUS_COLORS[k % len(STATUS_COLORS)]}), row=1, col=col)
    fig.update_xaxes(type="log", title_text="δ", exponentformat="power")
    fig.update_yaxes(type="log", row=1, col=2)
    fig.update_layout(height=420, title={"text": "Effect of δ on U and P (paper: barely changes for δ ≤ 1e-2)",
                                         "font": {"size": 14}})
    return fig


def _delta_table(sd) -> str:
    scan = _scan_names(sd)[0]
    scans = _labels(sd, scan)
    if "delta" not in scans:
        return ""
    idx = np.flatnonzero(_v(sd, scan) == scans.index("delta"))
    rows = ""
    for m in sorted(set(int(x) for x in _v(sd, "motion")[idx])):
        sel = idx[_v(sd, "motion")[idx] == m]
        d = _v(sd, "delta")[sel]
        finest = sel[np.argmin(d)]
        U0, P0 = _v(sd, "U_ref")[finest], _v(sd, "P_ref")[finest]
        with np.errstate(invalid="ignore", divide="ignore"):
            du = np.nanmax(np.abs(_v(sd, "U_ref")[sel] - U0)) / abs(U0)
            dp = np.nanmax(np.abs(_v(sd, "P_ref")[sel] - P0)) / abs(P0)
        rows += (f"<tr><td>{esc(_labels(sd, 'motion')[m])}</td><td class='num'>{d.max():.0e}…{d.min():.0e}</td>"
                 f"<td class='num'>{_fmt(du)}</td><td class='num'>{_fmt(dp)}</td></tr>")
    return scroll_table("<table><tr><th>motion</th><th>δ range</th><th>max |ΔU|/|U| vs smallest δ</th>"
                        f"<th>max |ΔP|/P</th></tr>{rows}</table>")


def _fallback_text(sd) -> str:
    if "used_method" not in sd.ds:
        return ""
    used, methods = _v(sd, "used_method"), _labels(sd, "method")
    parts = []
    for a, m in enumerate(methods):
        fell = int(np.count_nonzero((used[:, a] >= 0) & (used[:, a] != a)))
        none = int(np.count_nonzero(used[:, a] == -1))
        parts.append(f"{m}: {fell} solves answered by the fallback, {none} without any answer")
    fb = sd.science.get("solver", {}).get("fallback", "none")
    return f"<p>Fallback <code>{esc(fb)}</code> (answer kept per solve in <code>used_method</code>): " \
           + "; ".join(parts) + ".</p>"


def _failed_solves(sd) -> str:
    st, methods = _v(sd, "status"), _labels(sd, "method")
    meanings = sd.ds["status"].attrs.get("flag_meanings", {})
    rows = ""
    for i in np.argwhere(st > 0):
        p, a, b = i
        rows += (f"<tr><td>{esc(point_label(sd, p))}</td><td>{esc(methods[a])}</td>"
                 f"<td class='num'>{_v(sd, 'rtol')[b]:.0e}</td><td>{int(st[p, a, b])}: "
                 f"{esc(meanings.get(str(int(st[p, a, b])), '?'))}</td>"
                 f"<td class='num'>{_v(sd, 'seconds')[p, a, b]:.2g}</td></tr>")
    return (f"<details><summary>Every failed solve ({int(np.count_nonzero(st > 0))})</summary>"
            + scroll_table("<table><tr><th>point</th><th>method</th><th>rtol</th><th>status</th><th>seconds</th></tr>"
                           f"{rows}</table>") + "</details>")


def _stiffness_body(site, sd) -> list[str]:
    parts = [_timing_note(sd), site.guarded(f"{sd.name} reference", lambda: _reference_table(sd)),
             "<h4>Status of every solve</h4>", site.guarded(f"{sd.name} status", lambda: _status_table(sd)),
             site.guarded(f"{sd.name} fallback", lambda: _fallback_text(sd)),
             site.guarded(f"{sd.name} failures", lambda: _failed_solves(sd))]
    for j, parameter in enumerate(_labels(sd, _scan_names(sd)[0])):
        parts.append(f"<h4>Scan of {esc(parameter)}</h4>")
        parts.append(site.guarded(f"{sd.name} maps {parameter}", lambda j=j: site.figure(_scan_maps(sd, j))))
    parts.append("<h4>U and P against δ</h4>")
    parts.append(site.guarded(f"{sd.name} delta", lambda: site.maybe_figure(_delta_figure(sd)) + _delta_table(sd)))
    return parts


# ---------------------------------------------------------------------------
# Section
# ---------------------------------------------------------------------------


def _provenance(sd) -> str:
    sc = sd.science
    sol = sc.get("solver", {})
    return provenance_table(sd, [
        ("points", f"{sd.ds.sizes['point']} ({len(sc.get('motions', []))} motions, "
                   f"{len(sc.get('scans', sc.get('sweeps', [])))} scans)"),
        ("solvers", f"{', '.join(sol.get('methods', []))} at rtol "
                    f"{', '.join(f'{r:.0e}' for r in sol.get('rtols', []))}"
                    + (f"; fixed grids {sol.get('fixed_steps')}" if sol.get("fixed_steps") else "")
                    + (f"; fallback {sol.get('fallback')}" if sol.get("fallback", "none") != "none" else "")),
    ])


def study_section(site, sd, anchor: str) -> str:
    """The HTML of one study store's view: title (h3 with id ``anchor``), then its parts (h4)."""
    parts = [f"<h3 id='{anchor}'>{esc(sd.name)}: {esc(sd.title)} (study <code>{esc(sd.meta.get('kind'))}</code>)</h3>"]
    if not sd.complete:
        parts.append(f"<p class='warn'>This store is incomplete (run interrupted or still running): state "
                     f"{esc(sd.state)}. Points not computed yet are blank.</p>")
    parts.append(site.guarded(f"{sd.name} provenance", lambda: _provenance(sd)))
    body = _accuracy_body if sd.meta.get("kind") == "accuracy" else _stiffness_body
    parts += body(site, sd)
    parts.append(site.guarded(f"{sd.name} honesty", lambda: honesty_section(honesty_records(sd))))
    return "\n".join(parts)


def combined_honesty(studies) -> str | None:
    """The honest-tolerance view over the study stores ``studies`` together (h3
    ``honest-tolerances``; None without any)."""
    if not studies:
        return None
    records = [r for sd in studies for r in honesty_records(sd)]
    names = ", ".join(sd.name for sd in studies)
    return ("<h3 id='honest-tolerances'>Honest tolerances over every study</h3>"
            + honesty_section(records, f"Every solve of {names}"))
