"""Sections of optima stores (scene kind "optima"): the optimal Fourier motions.

Panels of figures OptMotionsLowMun/HighMun and OptMotionsp0p5/p1/p1p5, one set per force-law
exponent p: phi(tau) over one period of the best optimum for each Kmax, coloured by
mu_n/mu_s; lambda/lambda_ub and the scaled period against mu_n/mu_s for each Kmax (every kept
distinct optimum as a faint marker, the best as a line).  Hover shows the values and the
Fourier coefficients.  Tables: provenance, and the optimiser's stop reasons, ill-conditioning
and cost per (Kmax, p).
"""

from __future__ import annotations

import math

import numpy as np

from ._figure import subplots
from ._labels import axis_spec, param_label
from ._site import esc, provenance_table, scroll_table

__all__ = ["optima_section", "KIND_VERSION"]

#: version of the optima layout this report reads (pipeline._optima.KIND_VERSION)
KIND_VERSION = 3
#: marker symbols per Kmax as in the paper: squares, plusses, triangles, crosses
_SYMBOLS = ["square", "cross-thin-open", "triangle-up", "x-thin-open", "diamond", "circle"]
_STOP_NAMES = ("gradient_tolerance", "max_iterations", "line_search_failed", "ill_conditioned",
               "solve_failed", "no_progress", "error")


def _ratio_spec(sd):
    return axis_spec("anisotropy_ratio", sd.ds["anisotropy_ratio"].values, "log2")


def _ratio_colors(positions):
    import plotly.colors as pc

    lo, hi = float(np.min(positions)), float(np.max(positions))
    span = hi - lo or 1.0
    return [pc.sample_colorscale("Turbo", [0.05 + 0.9 * (x - lo) / span])[0] for x in positions]


def _coefficient_text(coefficients, kmax: int, names) -> str:
    k_largest = (len(coefficients) - 1) // 2
    keep = list(range(kmax + 1)) + list(range(k_largest + 1, k_largest + 1 + kmax))
    return ", ".join(f"{names[i]} = {coefficients[i]:.4g}" for i in keep)


def _provenance_rows(sd) -> str:
    sc = sd.science
    shape = sd.meta.get("layout", {}).get("shape", [])
    n = int(np.prod(shape)) if shape else 0
    axes = sc.get("axes", {})
    opt, keep, starts = sc.get("optimizer", {}), sc.get("keep", {}), sc.get("starts", {})
    ratios = axes.get("anisotropy_ratio", [])
    ratio_text = (f"2<sup>{math.log2(ratios[0]):g}</sup> … 2<sup>{math.log2(ratios[-1]):g}</sup> "
                  f"({len(ratios)} values)") if ratios else "?"
    return provenance_table(sd, [
        ("ensemble", f"μ<sub>n</sub>/μ<sub>s</sub> {ratio_text} × K<sub>max</sub> "
                     f"{esc(axes.get('max_wavenumber'))} × p {esc(axes.get('p'))} × "
                     f"{esc(starts.get('num'))} starts = {n:,} optimisations"),
        ("starts", f"A<sub>0</sub>, A<sub>1</sub> uniform on (0, 1), other coefficients 0, scaled "
                   f"period {esc(starts.get('scaled_period'))}, seed {esc(starts.get('seed'))}"),
        ("optimiser", f"BFGS + Newton, exact adjoint gradients; objective {esc(opt.get('objective'))}, "
                      f"direction {esc(opt.get('direction'))}, gtol {esc(opt.get('gtol'))}, "
                      f"at most {esc(opt.get('max_iterations'))} steps per grid round, τ grid "
                      f"rtol {esc(opt.get('grid_rtol'))}"),
        ("kept optima", f"{esc(keep.get('best'))} best distinct per cell among stop reasons "
                        f"{esc(', '.join(keep.get('accept', [])))}; equal when max |Δφ| ≤ "
                        f"{esc(keep.get('phi_tolerance'))} rad (modulo phase shift and φ → −φ) and "
                        f"scaled periods within {esc(keep.get('period_tolerance'))} (relative)"),
    ])


def _grid_error_text(sd, ik, ip) -> str:
    """Median / max of the starts' fixed-grid errors of lambda in one (Kmax, p), and how many
    exceed 1e-3 (``pipeline._optima``'s grid_error)."""
    if "grid_error" not in sd.ds:
        return "n/a"
    err = np.asarray(sd.array("grid_error")[:, ik, ip, :], dtype=float)
    err = err[np.isfinite(err)]
    if not err.size:
        return "n/a"
    return f"{np.median(err):.1e} / {err.max():.1e}; {int(np.count_nonzero(err > 1e-3))}"


def _outcomes_table(sd) -> str:
    """Stop reasons, ill-conditioning and cost per (p, Kmax)."""
    ds = sd.ds
    status = np.asarray(ds["status"].values)
    ill = np.asarray(ds["ill_conditioned"].values)
    seconds = np.asarray(ds["seconds"].values)
    meanings = ds["status"].attrs.get("flag_meanings", {})
    kmax = ds["max_wavenumber"].values
    ps = ds["p"].values
    head = ("<tr><th>p</th><th>K<sub>max</sub></th><th>optimisations</th>"
            + "".join(f"<th title='{esc(meanings.get(str(c), ''))}'>{esc(name.replace('_', ' '))}</th>"
                      for c, name in enumerate(_STOP_NAMES))
            + "<th>ill-conditioned</th><th>period at its bound</th>"
              "<th>seconds per optimisation (median / max)</th>"
              "<th>distinct optima kept (mean per ratio)</th>"
              "<th title='|lambda on the optimiser&#39;s fixed grid - the engine&#39;s at rtol 1e-8| / "
              "|the engine&#39;s| at each start&#39;s end'>fixed-grid error of λ (median / max; "
              "starts above 10<sup>-3</sup>)</th></tr>")
    rows = []
    kept = np.asarray(ds["optimum_start"].values) >= 0
    for ip, p in enumerate(ps):
        for ik, k in enumerate(kmax):
            st = status[:, ik, ip, :]
            done = st >= 0
            counts = "".join(f"<td class='num'>{int(np.count_nonzero(st == c))}</td>"
                             for c in range(len(_STOP_NAMES)))
            sec = seconds[:, ik, ip, :][done]
            sec_text = f"{np.median(sec):.2f} / {np.max(sec):.2f}" if sec.size else "n/a"
            n_ill = int(np.count_nonzero(ill[:, ik, ip, :] == 1))
            n_bound = (int(np.count_nonzero(sd.array("period_at_bound")[:, ik, ip, :] == 1))
                       if "period_at_bound" in ds else "n/a")
            rows.append(f"<tr><td class='num'>{p:g}</td><td class='num'>{int(k)}</td>"
                        f"<td class='num'>{int(done.sum())} / {st.size}</td>{counts}"
                        f"<td class='num'>{n_ill} ({100 * n_ill / max(int(done.sum()), 1):.0f} %)</td>"
                        f"<td class='num'>{n_bound}</td><td class='num'>{sec_text}</td>"
                        f"<td class='num'>{kept[:, ik, ip, :].sum(axis=-1).mean():.1f}</td>"
                        f"<td class='num'>{_grid_error_text(sd, ik, ip)}</td></tr>")
    n_done = int(np.count_nonzero(status >= 0))
    converged = int(np.count_nonzero(status == 0))
    return (f"<h4>Optimisations, stop reasons and cost</h4><p>{n_done:,} of {status.size:,} "
            f"optimisations computed; {converged:,} converged to the gradient tolerance. Starts "
            "flagged ill-conditioned ended with the Hessian's condition number above its threshold "
            "or the period at its bound (p → 2, where λ becomes invariant under T); they are "
            "reported, not retried.</p>"
            + scroll_table(f"<table>{head}{''.join(rows)}</table>"))


def _hover(sd, ir, ik, ip, rank) -> str:
    ds = sd.ds
    names = ds["coefficient"].attrs.get("names") or [str(i) for i in ds["coefficient"].values]
    a = sd.array
    k = int(a("max_wavenumber")[ik])
    c = a("optimum_coefficients")[ir, ik, ip, rank]
    ratio = float(a("anisotropy_ratio")[ir])
    return (f"μ<sub>n</sub>/μ<sub>s</sub> = 2<sup>{math.log2(ratio):.3g}</sup>, K<sub>max</sub> = {k}, "
            f"p = {float(a('p')[ip]):g}, rank {rank}<br>"
            f"λ/λ<sub>ub</sub> = {float(a('optimum_relative_efficiency')[ir, ik, ip, rank]):.5g}, "
            f"scaled period = {float(a('optimum_scaled_period')[ir, ik, ip, rank]):.5g}, "
            f"found by {int(a('optimum_multiplicity')[ir, ik, ip, rank])} start(s)<br>"
            + _coefficient_text(c, k, names))


def phi_figure(sd, ip: int):
    """phi(tau) of the best optimum of every ratio, one panel per Kmax, coloured by mu_n/mu_s."""
    ds = sd.ds
    kmax = ds["max_wavenumber"].values
    spec = _ratio_spec(sd)
    colors = _ratio_colors(spec.positions)
    tau = np.append(ds["tau"].values, 1.0)
    fig = subplots(rows=1, cols=len(kmax), shared_yaxes=True, horizontal_spacing=0.03,
                   subplot_titles=[f"K<sub>max</sub> = {int(k)}" for k in kmax])
    for ik in range(len(kmax)):
        for ir, color in enumerate(colors):
            phi = sd.array("optimum_phi")[ir, ik, ip, 0]
            if not np.isfinite(phi).any():
                continue
            text = _hover(sd, ir, ik, ip, 0)
            fig.add_trace(dict(type="scatter", x=tau, y=np.append(phi, phi[0]), mode="lines",
                               line={"color": color, "width": 1.6}, showlegend=False,
                               hovertemplate=f"τ = %{{x:.3f}}, φ = %{{y:.4f}} rad<br>{text}<extra></extra>"),
                          row=1, col=ik + 1)
        fig.update_xaxes(title_text="τ", range=[0, 1], row=1, col=ik + 1)
    fig.update_yaxes(title_text="φ (rad)", row=1, col=1)
    # the colour scale of mu_n/mu_s, as a marker-only trace with a colour bar
    fig.add_trace(dict(
        type="scatter", x=[None], y=[None], mode="markers", showlegend=False, hoverinfo="skip",
        marker={"color": [float(spec.positions.min())], "cmin": float(spec.positions.min()),
                "cmax": float(spec.positions.max()), "colorscale": "Turbo", "showscale": True,
                "colorbar": {"title": {"text": "μ<sub>n</sub>/μ<sub>s</sub>"}, "tickmode": "array",
                             "tickvals": list(spec.tickvals), "ticktext": list(spec.ticktext)}}))
    p = float(ds["p"].values[ip])
    fig.update_layout(height=360, margin={"t": 70, "l": 60, "r": 20, "b": 50},
                      title={"text": f"Best optimal φ(τ), p = {p:g}, coloured by μ<sub>n</sub>/μ<sub>s</sub>",
                             "font": {"size": 14}, "x": 0.01}, hoverlabel={"align": "left"})
    return fig


def efficiency_period_figure(sd, ip: int):
    """lambda/lambda_ub and scaled period against mu_n/mu_s per Kmax: kept optima and the best."""
    ds = sd.ds
    kmax = ds["max_wavenumber"].values
    spec = _ratio_spec(sd)
    p = float(ds["p"].values[ip])
    n_rank = ds.sizes["rank"]
    fig = subplots(rows=2, cols=1, shared_xaxes=True, vertical_spacing=0.06)
    palette = ["#1f77b4", "#d62728", "#2ca02c", "#9467bd", "#ff7f0e", "#8c564b"]
    for row, name in ((1, "optimum_relative_efficiency"), (2, "optimum_scaled_period")):
        for ik, k in enumerate(kmax):
            color, symbol = palette[ik % len(palette)], _SYMBOLS[ik % len(_SYMBOLS)]
            values = sd.array(name)[:, ik, ip, :]
            xs, ys, texts = [], [], []
            for ir in range(values.shape[0]):
                for rank in range(n_rank):
                    if np.isfinite(values[ir, rank]):
                        xs.append(float(spec.positions[ir]))
                        ys.append(float(values[ir, rank]))
                        texts.append(_hover(sd, ir, ik, ip, rank))
            if xs:
                fig.add_trace(dict(type="scatter", x=xs, y=ys, mode="markers", opacity=0.35,
                                   marker={"color": color, "symbol": symbol, "size": 7},
                                   name=f"K<sub>max</sub> = {int(k)}, kept optima",
                                   legendgroup=f"k{k}", showlegend=row == 1, text=texts,
                                   hovertemplate="%{text}<extra></extra>"), row=row, col=1)
            best = values[:, 0]
            fig.add_trace(dict(type="scatter", x=spec.positions, y=best, mode="lines+markers",
                               line={"color": color, "width": 2},
                               marker={"color": color, "symbol": symbol, "size": 9},
                               name=f"K<sub>max</sub> = {int(k)}, best", legendgroup=f"k{k}",
                               showlegend=row == 1,
                               text=[_hover(sd, ir, ik, ip, 0) for ir in range(len(best))],
                               hovertemplate="%{text}<extra></extra>"), row=row, col=1)
    fig.update_yaxes(title_text="λ/λ<sub>ub</sub>", row=1, col=1)
    periods = sd.array("optimum_scaled_period")[:, :, ip, :]
    periods = periods[np.isfinite(periods) & (periods > 0)]
    lo, hi = ((math.floor(np.log2(periods.min())), math.ceil(np.log2(periods.max())))
              if periods.size else (0, 1))
    ticks = list(range(lo, hi + 1, max(1, math.ceil((hi - lo + 1) / 8))))
    fig.update_yaxes(title_text=param_label("scaled_period", p), type="log", tickmode="array",
                     tickvals=[2.0 ** t for t in ticks],
                     ticktext=[f"2<sup>{t}</sup>" if t else "1" for t in ticks], row=2, col=1)
    fig.update_xaxes(tickmode="array", tickvals=list(spec.tickvals), ticktext=list(spec.ticktext))
    fig.update_xaxes(title_text=spec.title, row=2, col=1)
    fig.update_layout(height=620, margin={"t": 60, "l": 70, "r": 20, "b": 50},
                      title={"text": f"Relative efficiency and scaled period of the optima, p = {p:g}",
                             "font": {"size": 14}, "x": 0.01}, hoverlabel={"align": "left"})
    return fig


def best_table(sd) -> str:
    """The best |lambda|/lambda_ub per Kmax at every ratio (the numbers of the curves)."""
    ds = sd.ds
    kmax = ds["max_wavenumber"].values
    spec = _ratio_spec(sd)
    best = np.asarray(ds["optimum_relative_efficiency"].values[..., 0])
    period = np.asarray(ds["optimum_scaled_period"].values[..., 0])
    parts = []
    for ip, p in enumerate(ds["p"].values):
        head = "<tr><th>μ<sub>n</sub>/μ<sub>s</sub></th>" + "".join(
            f"<th>K<sub>max</sub> = {int(k)}: λ/λ<sub>ub</sub> (scaled period)</th>" for k in kmax) + "</tr>"
        rows = "".join(
            f"<tr><td>{spec.ticktext[list(spec.tickvals).index(x)] if x in spec.tickvals else f'2<sup>{x:g}</sup>'}</td>"
            + "".join(f"<td class='num'>{best[ir, ik, ip]:.4g} ({period[ir, ik, ip]:.3g})</td>"
                      for ik in range(len(kmax))) + "</tr>"
            for ir, x in enumerate(spec.positions))
        parts.append(f"<details><summary>best optima, p = {p:g}</summary>"
                     + scroll_table(f"<table>{head}{rows}</table>") + "</details>")
    return "".join(parts)


def optima_section(site, sd, anchor: str) -> str:
    """The HTML of one optima store's section (figures through ``site.figure``)."""
    version = sd.meta.get("kind_version")
    parts = [f"<h3 id='{anchor}'>{esc(sd.name)}: {esc(sd.title)}</h3>"]
    if version != KIND_VERSION:
        parts.append(f"<p class='warn'>optima store layout version {esc(version)} is not the version "
                     f"this report reads ({KIND_VERSION}); rerun the scene.</p>")
        return "\n".join(parts)
    if not sd.complete:
        parts.append("<p class='warn'>This store is incomplete (run interrupted or still running): "
                     f"state {esc(sd.state)}. Optima not computed yet are blank.</p>")
    parts.append(site.guarded(f"{sd.name} provenance", lambda: _provenance_rows(sd)))
    parts.append(site.guarded(f"{sd.name} outcomes", lambda: _outcomes_table(sd)))
    parts.append("<h4>Optimal motions</h4><p class='note'>Kept optima are shown in the orientation "
                 "U &lt; 0 (φ → π − φ applied to optima found moving forwards), as the paper "
                 "(which minimised λ). Markers: every kept distinct optimum (faint); lines: the best.</p>")
    parts.append(site.guarded(f"{sd.name} best table", lambda: best_table(sd)))
    for ip in range(sd.ds.sizes["p"]):
        parts.append(site.guarded(f"{sd.name} phi p[{ip}]", lambda ip=ip: site.figure(phi_figure(sd, ip))))
        parts.append(site.guarded(f"{sd.name} optima p[{ip}]",
                                  lambda ip=ip: site.figure(efficiency_period_figure(sd, ip))))
    return "\n".join(parts)
