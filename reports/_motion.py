"""Motions of an optimum: u(tau) from the solver, body snapshots with the force along the body,
the body's path, and a Plotly animation of the body sliding over a few periods.

Geometry (paper, section "Model"; ``solver/model/force.py``).  Lengths are in body lengths L, time in
periods (tau = t/T).  The upper link, 0 <= s <= 1/2 from the apex, is at

    x(s) = x_cm + (s - 1/4) cos(phi),    y(s) = s sin(phi),

the lower link is its mirror image y -> -y, and x_cm(tau) = int_0^tau u dtau' (u = T dx_cm/dt).
The horizontal force per unit length on the upper link (equal on the lower one by symmetry) is

    f_x(s) = (mu_n S w - mu_s C c) r^(p-1),  w = -u S - omega S^2/4 + omega s,  c = C (u + omega S/4),
    r^2 = w^2 + c^2 + delta_tau^2,  S = sin(phi), C = cos(phi), omega = dphi/dtau, delta_tau = T delta,

with mu_n mu_s = 1 (the scaled problem the pipeline solves).
"""

from __future__ import annotations

import re
from dataclasses import dataclass

import numpy as np

from ._figure import Figure, encode_trace, subplots
from ._labels import format_value, param_label

__all__ = ["Motion", "compute_motion", "force_density", "body_outline", "motion_figure", "animation_figure"]

#: Points per link where the force arrow is drawn.
N_ARROWS = 6


def force_density(u, phi, omega, mu_n, mu_s, p, delta_tau, s):
    """Horizontal force per unit length f_x(s) on the upper link.

    Parameters
    ----------
    u, phi, omega : ndarray, shape (n_tau,)
        Scaled velocity, half-opening angle [rad], dphi/dtau [rad per period].
    s : ndarray, shape (n_s,)
        Arc length from the apex along the link, in [0, 1/2].

    Returns
    -------
    ndarray, shape (n_tau, n_s)
    """
    u, phi, omega = (np.asarray(x, dtype=np.float64)[:, None] for x in (u, phi, omega))
    S, C = np.sin(phi), np.cos(phi)
    w = -u * S - omega * S * S / 4.0 + omega * np.asarray(s)[None, :]
    c = C * (u + omega * S / 4.0)
    r = np.sqrt(w * w + c * c + delta_tau * delta_tau)
    return (mu_n * S * w - mu_s * C * c) * r ** (p - 1.0)


def body_outline(x_cm, phi):
    """Tip of the upper link, apex, tip of the lower link: x, y each shape (n_tau, 3)."""
    x_cm, phi = np.asarray(x_cm, dtype=np.float64), np.asarray(phi, dtype=np.float64)
    c, s = np.cos(phi), np.sin(phi)
    x = np.stack([x_cm + c / 4, x_cm - c / 4, x_cm + c / 4], axis=-1)
    y = np.stack([s / 2, np.zeros_like(s), -s / 2], axis=-1)
    return x, y


@dataclass(frozen=True)
class Motion:
    """A solved periodic motion on a uniform tau grid of one period.

    tau : shape (n,), k/n; u, phi, omega, x_cm : shape (n,); x_cm(0) = 0.
    displacement : x_cm after one period (T U, body lengths).
    """

    label: str
    params: dict
    value_text: str
    tau: np.ndarray
    u: np.ndarray
    phi: np.ndarray
    omega: np.ndarray
    x_cm: np.ndarray
    displacement: float
    mu_n: float
    mu_s: float
    p: float
    delta_tau: float
    status: int
    error_estimate: float

    def forces(self, s):
        return force_density(self.u, self.phi, self.omega, self.mu_n, self.mu_s, self.p, self.delta_tau, s)

    def x_cm_at(self, tau):
        """x_cm at any tau >= 0 (periodic part plus the drift of whole periods)."""
        tau = np.asarray(tau, dtype=np.float64)
        k = np.floor(tau)
        frac = tau - k
        ext_t = np.append(self.tau, 1.0)
        ext_x = np.append(self.x_cm, self.displacement)
        return k * self.displacement + np.interp(frac, ext_t, ext_x)

    def at(self, tau):
        """u, phi, omega at any tau (periodic interpolation)."""
        frac = np.mod(np.asarray(tau, dtype=np.float64), 1.0)
        ext_t = np.append(self.tau, 1.0)
        return tuple(np.interp(frac, ext_t, np.append(a, a[0])) for a in (self.u, self.phi, self.omega))


def _kinematics(solver, family: str, q: dict):
    if family == "fourier":
        from pipeline._grid import fourier_kinematics

        return fourier_kinematics(solver, {k: np.array([float(v)]) for k, v in q.items()})
    A0 = np.array([q["A0"]])
    A1 = A0 * q["A1_ratio"]
    if family == "harmonic":
        return solver.Harmonic(A0=A0, A1=A1)
    closing, opening = float(q["closing_shape"]), float(q["opening_shape"])
    return solver.PowerLaw(A0, A1, np.array([q["duty_cycle"]]), np.array([abs(closing)]), np.array([closing > 1]),
                           np.array([abs(opening)]), np.array([opening > 1]))


def scaled_friction(q: dict) -> tuple[float, float]:
    """(mu_n/mu_s, scaled period) from scene parameters given either as that pair or as T^(2-p) mu_{n,s}."""
    if "anisotropy_ratio" in q:
        return float(q["anisotropy_ratio"]), float(q["scaled_period"])
    a, b, p = float(q["T2_mu_n"]), float(q["T2_mu_s"]), float(q.get("p", 0.0))
    return a / b, (a * b) ** (1.0 / (4.0 - 2.0 * p))


def compute_motion(family: str, params: dict, *, rtol: float, method: str = "periodic", n_tau: int = 256,
                   label: str = "", value_text: str = "") -> Motion:
    """Solve the periodic motion at ``params`` (every scene parameter) and resample it uniformly.

    Raises
    ------
    RuntimeError
        When the solver does not converge at this point (message gives the status reason).
    """
    import solver

    q = dict(params)
    ratio, scaled_period = scaled_friction(q)
    p, delta = float(q.get("p", 0.0)), float(q.get("delta", 1e-5))
    phys = solver.Physics.from_scaled(anisotropy_ratio=np.array([ratio]), scaled_period=np.array([scaled_period]),
                                      p=np.array([p]), delta=np.array([delta]))
    kin = _kinematics(solver, family, q)
    res = solver.solve_periodic(kin, phys, method=method, rtol=rtol, return_series=True)
    status = int(res.status[0])
    if status != 0:
        raise RuntimeError(f"solver status {status}: {solver.status_reason(status, method)}")
    tn = np.asarray(res.tau[0], dtype=np.float64)
    un = np.asarray(res.u[0], dtype=np.float64)
    ok = np.isfinite(tn) & np.isfinite(un) & (tn < 1.0)  # final grids may be padded; tau = 1 closes the period
    tn, un = tn[ok], un[ok]
    order = np.argsort(tn)
    tn, un = tn[order], un[order]
    # x_cm on the solver's own (refined) nodes, where u is accurate, then resampled.
    t_ext, u_ext = np.append(tn, 1.0), np.append(un, un[0])
    x_nodes = np.concatenate([[0.0], np.cumsum(0.5 * (u_ext[1:] + u_ext[:-1]) * np.diff(t_ext))])
    # The solver's own int u dtau (T U) is more accurate than this trapezoid; the small difference
    # is spread linearly over the period so the drawn path drifts by exactly T U per period.
    displacement = float(res.mean_u[0])
    x_nodes = x_nodes + (displacement - x_nodes[-1]) * t_ext
    x0 = np.interp(tn[0], t_ext, x_nodes) if tn[0] > 0 else 0.0
    tau = np.arange(n_tau) / n_tau
    u = np.interp(tau, t_ext, u_ext)
    x_cm = np.interp(tau, t_ext, x_nodes) - x0
    phi = kin.angle(tau)[0]
    omega = kin.angle_rate(tau)[0]
    return Motion(label=label, params=q, value_text=value_text, tau=tau, u=u, phi=phi, omega=omega, x_cm=x_cm,
                  displacement=displacement, mu_n=float(phys.mu_n[0]), mu_s=float(phys.mu_s[0]), p=p,
                  delta_tau=float(phys.delta_tau[0]), status=status, error_estimate=float(res.error_estimate[0]))


# ---------------------------------------------------------------------------
# Figures
# ---------------------------------------------------------------------------


def params_text(params: dict, p: float = 0.0, sep: str = ", ") -> str:
    keys = [k for k in ("anisotropy_ratio", "scaled_period", "T2_mu_n", "T2_mu_s", "A0", "A1_ratio", "duty_cycle",
                        "closing_shape", "opening_shape") if k in params]
    keys += sorted((k for k in params if re.match(r"^[AB][1-9]\d*$", k)), key=lambda k: (int(k[1:]), k[0]))
    return sep.join(f"{param_label(k, p)} = {format_value(k, params[k])}" for k in keys)


def _arrows(x_body, y_body, fx, scale):
    """Horizontal arrows from body points (shape (m,)) of length scale * fx: segment trace + tip markers."""
    xs, ys = [], []
    for xb, yb, f in zip(x_body, y_body, fx):
        xs += [xb, xb + scale * f, None]
        ys += [yb, yb, None]
    tips_x = x_body + scale * fx
    symbols = np.where(fx >= 0, "triangle-right", "triangle-left")
    return xs, ys, tips_x, symbols


def _force_scale(m: Motion, s) -> float:
    f = m.forces(s)
    fmax = float(np.nanmax(np.abs(f))) if f.size else 0.0
    return 0.2 / fmax if fmax > 0 else 0.0  # longest arrow: 0.2 body lengths


def _snapshot_geometry(m: Motion, tau_k: float, s, scale: float, x_shift: float = 0.0):
    u, phi, omega = (np.atleast_1d(a) for a in m.at(tau_k))
    xc = float(m.x_cm_at(tau_k)) + x_shift
    fx = force_density(u, phi, omega, m.mu_n, m.mu_s, m.p, m.delta_tau, s)[0]
    cx, sy = np.cos(phi[0]), np.sin(phi[0])
    xu = xc + (s - 0.25) * cx
    yu = s * sy
    body_x = [xc + cx / 4, xc - cx / 4, xc + cx / 4]
    body_y = [sy / 2, 0.0, -sy / 2]
    bx = np.concatenate([xu, xu])
    by = np.concatenate([yu, -yu])
    ff = np.concatenate([fx, fx])
    return body_x, body_y, bx, by, ff, xc, float(phi[0]), float(u[0])


def motion_figure(m: Motion, p: float = 0.0, n_snapshots: int = 8):
    """Body snapshots through one period with force arrows (top); u(tau), phi(tau) and the path
    over three periods (bottom)."""
    fig = subplots(rows=2, cols=3, row_heights=[0.45, 0.55], horizontal_spacing=0.08, vertical_spacing=0.16,
                   specs=[[{"colspan": 3}, None, None], [{}, {}, {}]],
                   subplot_titles=("body at eight instants of one period, side by side (arrows: horizontal "
                                   "force per unit length f<sub>x</sub>(s))", "u(τ)", "φ(τ)",
                                   "positions over three periods"))
    s = (np.arange(N_ARROWS) + 0.5) / (2 * N_ARROWS)
    scale = _force_scale(m, s)
    gap = 1.3  # horizontal spacing of the snapshots [body lengths]; each also moved by its own x_cm
    tick_x, tick_t = [], []
    for k in range(n_snapshots):
        tk = k / n_snapshots
        body_x, body_y, bx, by, ff, xc, phi, u = _snapshot_geometry(m, tk, s, scale, x_shift=gap * k)
        hover = (f"τ = {tk:.3f}<br>φ = {phi:.3f} rad<br>u = {u:.4g}<br>x<sub>cm</sub> = {xc - gap * k:.4g}"
                 "<extra></extra>")
        fig.add_trace(dict(type="scatter", x=body_x, y=body_y, mode="lines+markers",
                           line={"color": "#1f3b73", "width": 3}, marker={"size": 4},
                           name="body", legendgroup="body", showlegend=k == 0, hovertemplate=hover),
                      row=1, col=1)
        ax, ay, tx, sym = _arrows(bx, by, ff, scale)
        fig.add_trace(dict(type="scatter", x=ax, y=ay, mode="lines", line={"color": "#c0392b", "width": 1.5},
                           name="f<sub>x</sub>(s)", legendgroup="force", showlegend=k == 0, hoverinfo="skip"),
                      row=1, col=1)
        fig.add_trace(dict(type="scatter", x=tx, y=by, mode="markers",
                           marker={"symbol": sym, "size": 7, "color": "#c0392b"},
                           customdata=np.stack([ff, np.concatenate([s, s])], axis=-1), showlegend=False,
                           legendgroup="force",
                           hovertemplate=f"τ = {tk:.3f}<br>s = %{{customdata[1]:.3f}}<br>"
                                         "f<sub>x</sub> = %{customdata[0]:.4g}<extra></extra>"), row=1, col=1)
        tick_x.append(gap * k)
        tick_t.append(f"τ = {k}/{n_snapshots}")
    fig.update_xaxes(tickmode="array", tickvals=tick_x, ticktext=tick_t, showgrid=False, row=1, col=1,
                     title_text=f"snapshots {gap:g} body lengths apart, each at its own x<sub>cm</sub>(τ)")
    fig.update_yaxes(scaleanchor="x", scaleratio=1, range=[-0.6, 0.6], title_text="y", row=1, col=1)

    hov = params_text(m.params, p, "<br>")
    fig.add_trace(dict(type="scatter", x=m.tau, y=m.u, mode="lines", name="u(τ)", line={"color": "#1f77b4"},
                       hovertemplate="τ = %{x:.3f}<br>u = %{y:.4g}<br>" + hov + "<extra></extra>"), row=2, col=1)
    fig.add_hline(y=m.displacement, line={"dash": "dot", "color": "#888"}, row=2, col=1)
    fig.update_xaxes(title_text="τ = t/T", row=2, col=1)
    fig.update_yaxes(title_text="u = T dx<sub>cm</sub>/dt", row=2, col=1)
    fig.add_trace(dict(type="scatter", x=m.tau, y=m.phi, mode="lines", name="φ(τ)", line={"color": "#2ca02c"},
                       hovertemplate="τ = %{x:.3f}<br>φ = %{y:.4f} rad<extra></extra>"), row=2, col=2)
    fig.update_xaxes(title_text="τ = t/T", row=2, col=2)
    fig.update_yaxes(title_text="φ (rad)", row=2, col=2)

    t3 = np.linspace(0.0, 3.0, 3 * len(m.tau) + 1)
    xc = m.x_cm_at(t3)
    _, phi3, _ = m.at(t3)
    apex = xc - np.cos(phi3) / 4
    tips = xc + np.cos(phi3) / 4
    for y, name, color in ((xc, "x<sub>cm</sub>", "#1f3b73"), (apex, "apex", "#9467bd"), (tips, "link tips", "#ff7f0e")):
        fig.add_trace(dict(type="scatter", x=t3, y=y, mode="lines", name=name, line={"color": color},
                           hovertemplate="t/T = %{x:.3f}<br>x = %{y:.4g}<extra>" + name + "</extra>"),
                      row=2, col=3)
    fig.update_xaxes(title_text="t/T", row=2, col=3)
    fig.update_yaxes(title_text="x (body lengths)", row=2, col=3)
    fig.update_layout(height=680, margin={"t": 80, "l": 60, "r": 20, "b": 50},
                      legend={"orientation": "h", "y": 1.1, "x": 0.0})
    return fig


def animation_figure(m: Motion, p: float = 0.0, periods: int = 3, frames_per_period: int = 24) -> dict:
    """The body sliding over ``periods`` periods: Plotly frames with play/pause buttons and a slider.

    Returned as a figure dict (``data``, ``layout``, ``frames``)."""
    s = (np.arange(N_ARROWS) + 0.5) / (2 * N_ARROWS)
    scale = _force_scale(m, s)
    times = np.arange(periods * frames_per_period + 1) / frames_per_period

    def traces(t):
        body_x, body_y, bx, by, ff, xc, phi, u = _snapshot_geometry(m, t, s, scale)
        ax, ay, tx, sym = _arrows(bx, by, ff, scale)
        past = times[times <= t + 1e-12]
        return [
            dict(type="scatter", x=body_x, y=body_y, mode="lines+markers", line={"color": "#1f3b73", "width": 4},
                       marker={"size": 6}, name="body",
                       hovertemplate=f"t/T = {t:.3f}<br>φ = {phi:.3f} rad<br>u = {u:.4g}<extra></extra>"),
            dict(type="scatter", x=ax, y=ay, mode="lines", line={"color": "#c0392b", "width": 2}, name="f<sub>x</sub>(s)",
                       hoverinfo="skip"),
            dict(type="scatter", x=m.x_cm_at(past), y=np.zeros(past.size), mode="lines", line={"color": "#888", "dash": "dot"},
                       name="x<sub>cm</sub> trail", hoverinfo="skip"),
        ]

    x_all = m.x_cm_at(times)
    lo, hi = float(x_all.min()) - 0.55, float(x_all.max()) + 0.55
    frames = [{"name": f"{t:.3f}", "traces": [0, 1, 2], "data": [encode_trace(tr) for tr in traces(t)]}
              for t in times]
    play = {"frame": {"duration": 60, "redraw": False}, "fromcurrent": True, "transition": {"duration": 0},
            "mode": "immediate"}
    pause = {"frame": {"duration": 0, "redraw": False}, "mode": "immediate", "transition": {"duration": 0}}
    steps = [{"method": "animate", "label": f"{t:.2f}",
              "args": [[f"{t:.3f}"], {"frame": {"duration": 0, "redraw": False}, "mode": "immediate",
                                      "transition": {"duration": 0}}]} for t in times]
    fig = Figure(data=traces(0.0))
    fig.update_layout(
        height=480, margin={"t": 50, "l": 60, "r": 20, "b": 40},
        xaxis={"range": [lo, hi], "title": {"text": "x (body lengths)"}, "constrain": "domain"},
        yaxis={"range": [-0.6, 0.6], "scaleanchor": "x", "scaleratio": 1, "title": {"text": "y"}},
        title={"text": f"sliding over {periods} periods (TU = {m.displacement:.4g} per period)", "font": {"size": 13}},
        updatemenus=[{"type": "buttons", "direction": "left", "x": 0.0, "y": 1.12, "xanchor": "left",
                      "buttons": [{"label": "▶ play", "method": "animate", "args": [None, play]},
                                  {"label": "❚❚ pause", "method": "animate", "args": [[None], pause]}]}],
        sliders=[{"active": 0, "currentvalue": {"prefix": "t/T = "}, "pad": {"t": 30}, "steps": steps}],
    )
    out = fig.to_plotly_json()
    out["frames"] = frames
    return out
