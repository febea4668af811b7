"""The paper's symbols for parameters and quantities, and how each axis is drawn.

Labels use Plotly's pseudo-HTML (<sub>, <sup>), which works in axis titles and hover labels.
"""

from __future__ import annotations

import html
import math
import re
from dataclasses import dataclass

import numpy as np

__all__ = ["AxisSpec", "axis_spec", "param_label", "quantity_label", "format_value", "SIGNED", "tex_html"]

_MU = "μ<sub>n</sub>μ<sub>s</sub>"


def _exponent(p: float, num: int) -> str:
    """num/(4-2p) as a short fraction string (1/4 at p = 0)."""
    den = 4.0 - 2.0 * p
    if p == 0:
        return f"{num}/4"
    if p == 1:
        return f"{num}/2"
    return f"{num}/{den:g}"


def param_label(name: str, p: float = 0.0) -> str:
    """Axis label of parameter ``name`` in the paper's notation."""
    t2 = "T<sup>2</sup>" if p == 0 else f"T<sup>{2 - p:g}</sup>"
    return {
        "anisotropy_ratio": "μ<sub>n</sub>/μ<sub>s</sub>",
        "scaled_period": f"({_MU})<sup>{_exponent(p, 1)}</sup> T",
        "T2_mu_n": f"{t2} μ<sub>n</sub>",
        "T2_mu_s": f"{t2} μ<sub>s</sub>",
        "A0": "A<sub>0</sub>",
        "A1_ratio": "A<sub>1</sub>/A<sub>0</sub>",
        "duty_cycle": "τ<sub>0</sub>",
        "closing_shape": "closing power law",
        "opening_shape": "opening power law",
        "duty_cycle_halfwidth": "Δτ<sub>0</sub> (τ<sub>0</sub> window half-width)",
        "exponent_set": "allowed exponents",
        "p": "p",
        "delta": "δ",
    }.get(name, _fourier_label(name))


def _fourier_label(name: str) -> str:
    """A<sub>k</sub> / B<sub>k</sub> for a Fourier coefficient's name ("A3"), else the name."""
    m = re.match(r"^([AB])([1-9]\d*)$", name)
    return f"{m.group(1)}<sub>{m.group(2)}</sub>" if m else name


def quantity_label(name: str, p: float = 0.0) -> str:
    """Axis label of stored quantity ``name`` (scaled as in the paper)."""
    return {
        "U": "U",
        "P": "P",
        "efficiency": "λ",
        "scaled_speed": f"({_MU})<sup>-{_exponent(p, 1)}</sup> U",
        "scaled_power": f"({_MU})<sup>-{_exponent(p, 3)}</sup> P",
        "scaled_efficiency": f"({_MU})<sup>1/2</sup> λ",
        "relative_efficiency": "λ/λ<sub>ub</sub>",
        "efficiency_upper_bound": "λ<sub>ub</sub>",
        "displacement_per_period": "T U (body lengths per period)",
        "error_estimate": "solver error estimate",
        "iterations": "solver iterations",
        "n_tau": "τ-grid size",
    }.get(name, name)


#: Quantities that carry the sign of U (shown on a diverging colour scale centred at 0).
SIGNED = {"U", "efficiency", "scaled_speed", "scaled_efficiency", "relative_efficiency",
          "displacement_per_period"}

#: Parameters the paper plots on powers of two.
_POWER_OF_TWO_PARAMS = {"anisotropy_ratio", "scaled_period", "T2_mu_n", "T2_mu_s"}


def _shape_text(g: float) -> str:
    """Signed power-law exponent -> the scene file's spelling (up:g, down:g, linear)."""
    if abs(g) == 1:
        return "linear"
    return f"{'up' if g > 0 else 'down'}:{abs(g):g}"


def _pow2_text(v: float) -> str:
    k = math.log2(v)
    if abs(k - round(k)) < 1e-9:
        return f"2<sup>{int(round(k))}</sup>" if round(k) else "1"
    return f"2<sup>{k:.3g}</sup>"


def format_value(name: str, v: float) -> str:
    """One parameter value as text for titles and hover labels."""
    if v is None or (isinstance(v, float) and not math.isfinite(v)):
        return "n/a"
    if name in ("closing_shape", "opening_shape"):
        return _shape_text(float(v))
    if name in _POWER_OF_TWO_PARAMS and v > 0:
        k = math.log2(v)
        if abs(2 * k - round(2 * k)) < 1e-9:
            return _pow2_text(v)
    if name == "A0" or re.match(r"^[AB][1-9]\d*$", name):
        return f"{v:.4g} rad"
    return f"{v:.4g}"


@dataclass(frozen=True)
class AxisSpec:
    """How one parameter axis is drawn.

    ``positions`` are the plot coordinates of ``values`` (log2 of the value on power-of-two
    axes, the index on categorical ones); ``tickvals``/``ticktext`` label them in the
    parameter's own units, so the axis reads 2^-4, 1, 2^4 while hover shows the value.
    """

    name: str
    values: np.ndarray
    positions: np.ndarray
    title: str
    kind: str  # "linear", "log2" or "category"
    tickvals: tuple | None = None
    ticktext: tuple | None = None

    def axis_layout(self) -> dict:
        d = {"title": {"text": self.title}}
        if self.tickvals is not None:
            d.update(tickmode="array", tickvals=list(self.tickvals), ticktext=list(self.ticktext))
        return d


def axis_spec(name: str, values, spacing: str | None = None, p: float = 0.0) -> AxisSpec:
    """Choose linear, log2 or categorical drawing for a parameter axis from its values."""
    v = np.asarray(values, dtype=np.float64)
    title = param_label(name, p)
    if name in ("closing_shape", "opening_shape", "exponent_set"):
        pos = np.arange(v.size, dtype=np.float64)
        text = [_shape_text(x) if name != "exponent_set" else f"set {int(x)}" for x in v]
        return AxisSpec(name, v, pos, title, "category", tuple(pos.tolist()), tuple(text))
    log2 = spacing == "log2"
    if not log2 and name in _POWER_OF_TWO_PARAMS and v.size >= 2 and np.all(v > 0):
        k = np.log2(v)
        log2 = bool(np.all(np.abs(2 * k - np.round(2 * k)) < 1e-9))
    if log2 and np.all(v > 0):
        pos = np.log2(v)
        lo, hi = math.floor(pos.min() + 1e-9), math.ceil(pos.max() - 1e-9)
        step = max(1, math.ceil((hi - lo + 1) / 9))
        ticks = list(range(lo, hi + 1, step))
        return AxisSpec(name, v, pos, title, "log2", tuple(float(t) for t in ticks),
                        tuple(f"2<sup>{t}</sup>" if t else "1" for t in ticks))
    return AxisSpec(name, v, v.copy(), title, "linear")


# ---------------------------------------------------------------------------
# The paper's LaTeX in quoted sentences, as plain Unicode HTML (the report is offline: no MathJax)
# ---------------------------------------------------------------------------

#: TeX commands the paper's sentences use, and their Unicode characters.
TEX_SYMBOLS = {
    "mu": "μ", "pi": "π", "phi": "φ", "varphi": "φ", "lambda": "λ", "tau": "τ", "delta": "δ", "gamma": "γ",
    "eta": "η", "omega": "ω", "Omega": "Ω", "Pi": "Π", "alpha": "α", "beta": "β", "theta": "θ", "sigma": "σ",
    "epsilon": "ε", "kappa": "κ", "Delta": "Δ", "Gamma": "Γ", "Lambda": "Λ", "nu": "ν", "rho": "ρ", "xi": "ξ",
    "ll": "≪", "gg": "≫", "leq": "≤", "le": "≤", "geq": "≥", "ge": "≥", "neq": "≠", "approx": "≈", "sim": "∼",
    "to": "→", "rightarrow": "→", "infty": "∞", "times": "×", "cdot": "·", "pm": "±", "propto": "∝",
    "partial": "∂", "int": "∫", "sum": "∑", "sqrt": "√", "ldots": "…", "dots": "…", "cdots": "⋯",
    "quad": " ", "qquad": "  ", ",": " ", ";": " ", "!": "", " ": " ", "%": "%", "&": "&", "_": "_",
    "{": "{", "}": "}", "$": "$",
}
#: Commands whose braced argument is text (its braces dropped): \mbox{max} -> max.
_TEX_TEXT = ("mbox", "text", "textrm", "mathrm", "mathit", "textit", "emph", "operatorname", "mathbf", "textbf")

_TEX_TOKEN = re.compile(r"\\([A-Za-z]+|.)|([_^])|(\{)|(\})|(\$)|(~)|(--)|(.)", re.S)


def _tex_argument(tokens, k) -> tuple[str, int]:
    """(HTML of the argument starting at ``tokens[k]``: a braced group, a command or one
    character; the index after it)."""
    if k >= len(tokens):
        return "", k
    if tokens[k].group(3):
        depth, j = 1, k + 1
        while j < len(tokens) and depth:
            depth += 1 if tokens[j].group(3) else -1 if tokens[j].group(4) else 0
            j += 1
        return _tex_render(tokens[k + 1:j - 1]), j
    return _tex_render(tokens[k:k + 1]), k + 1


def _tex_render(tokens, math: bool = True) -> str:
    """HTML of ``tokens``; ``math``: inside ``$...$`` (where ``_``, ``^`` and braces act)."""
    out, k = [], 0
    while k < len(tokens):
        t = tokens[k]
        command, script = t.group(1), t.group(2)
        if command is not None and command in _TEX_TEXT and k + 1 < len(tokens) and tokens[k + 1].group(3):
            arg, k = _tex_argument(tokens, k + 1)
            out.append(arg)
            continue
        if t.group(5):
            math = not math
        elif not math and (script or t.group(3) or t.group(4)):
            out.append(html.escape(t.group(0)))
        elif script:
            tag = "sub" if script == "_" else "sup"
            arg, k = _tex_argument(tokens, k + 1)
            out.append(f"<{tag}>{arg}</{tag}>")
            continue
        elif command is not None:
            out.append(html.escape(TEX_SYMBOLS.get(command, command)))
        elif t.group(6):
            out.append("\u00a0")
        elif t.group(7):
            out.append("–")
        elif t.group(8) is not None:
            out.append(html.escape(t.group(8)))
        # (the braces of a bare group in math print nothing)
        k += 1
    return "".join(out)


def tex_html(text) -> str:
    """``text`` with the paper's LaTeX rendered as HTML: math (``$...$``) in Unicode with
    ``<sub>``/``<sup>``, ``\\mbox{..}`` as text, ``~`` a no-break space, ``--`` an en dash; every
    other character HTML-escaped.  ``$(\\mu_n \\mu_s)^{1/4}T \\to 0$`` -> ``(μ<sub>n</sub>
    μ<sub>s</sub>)<sup>1/4</sup>T → 0``."""
    return _tex_render(list(_TEX_TOKEN.finditer(str(text))), math=False)
