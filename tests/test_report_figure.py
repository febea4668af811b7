"""reports._figure builds the JSON plotly.py would build, without plotly.py's object model.

Each test builds one figure both ways, through plotly.py (``make_subplots``, ``go.Figure``) and
through ``reports._figure``, and compares the two JSON specs value by value (the template aside,
which the report replaces with its own). Negative controls: a different spacing, a different
shared-axes choice and a different colour scale must make the comparison fail.
"""

import itertools
import json

import numpy as np
import pytest

pytest.importorskip("plotly")

import plotly.graph_objects as go  # noqa: E402
from plotly.subplots import make_subplots  # noqa: E402

from reports._figure import Figure, colorscale, subplots  # noqa: E402


def _json(fig) -> dict:
    from plotly.io.json import to_json_plotly

    spec = fig.to_plotly_json()
    spec = {"data": spec.get("data", []), "layout": dict(spec.get("layout", {}))}
    spec["layout"].pop("template", None)
    return json.loads(to_json_plotly(spec))


GRIDS = [dict(rows=r, cols=c, shared_xaxes=sx, shared_yaxes=sy, horizontal_spacing=h, vertical_spacing=v)
         for (r, c), sx, sy, h, v in itertools.product([(1, 1), (1, 3), (2, 2), (3, 1), (4, 3)], [False, True],
                                                       [False, True], [None, 0.05], [None, 0.1])]


@pytest.mark.parametrize("kw", GRIDS, ids=lambda kw: "-".join(f"{k[:2]}{v}" for k, v in kw.items()))
def test_subplots_lay_out_as_make_subplots(kw):
    titles = [f"t{i}" if i % 3 else "" for i in range(kw["rows"] * kw["cols"])]
    for t in (None, titles):
        assert _json(subplots(**kw, subplot_titles=t)) == _json(make_subplots(**kw, subplot_titles=t))


def test_spans_and_row_heights_lay_out_as_make_subplots():
    kw = dict(rows=2, cols=3, row_heights=[0.45, 0.55], horizontal_spacing=0.08, vertical_spacing=0.16,
              specs=[[{"colspan": 3}, None, None], [{}, {}, {}]], subplot_titles=("a", "b", "c", "d"))
    assert _json(subplots(**kw)) == _json(make_subplots(**kw))
    kw = dict(rows=3, cols=2, column_widths=[2, 1], specs=[[{"rowspan": 2}, {}], [None, {}], [{}, {}]],
              shared_xaxes=True, shared_yaxes=True)
    assert _json(subplots(**kw)) == _json(make_subplots(**kw))


def _both(kw, build):
    ours, theirs = subplots(**kw), make_subplots(**kw)
    build(ours, dict)
    build(theirs, lambda **t: getattr(go, t.pop("type").capitalize())(**t))
    return _json(ours), _json(theirs)


def _calls(fig, trace):
    x = np.linspace(0.0, 1.0, 5)
    fig.add_trace(trace(type="scatter", x=x, y=x ** 2, mode="lines", line={"color": "#888"}), row=2, col=1)
    fig.add_trace(trace(type="heatmap", z=np.arange(6.0).reshape(2, 3), x=("a", "b", "c"), y=[1, 2],
                        colorscale="RdBu_r", zmin=0, zmax=5), row=1, col=2)
    fig.add_hline(y=0.5, line={"dash": "dot"}, row=2, col=1)
    fig.add_hline(y=0.5, line={"dash": "dot"}, row=2, col=2)  # no trace there: no line (plotly's rule)
    fig.update_xaxes(tickmode="array", tickvals=[0, 1], title_text="τ", title_font={"size": 10})
    fig.update_yaxes(title_text="u", title_standoff=4, row=2, col=1)
    fig.update_yaxes(type="log", row=1)
    fig.update_layout(height=500, coloraxis={"colorscale": "Viridis"}, title_text="t",
                      margin={"t": 80, "l": 60}, plot_bgcolor="white")
    fig.update_layout({"coloraxis2": {"colorscale": "Viridis", "colorbar": {"len": 0.4}}})
    fig.update_annotations(font_size=11)


def test_figure_calls_give_plotlys_json():
    ours, theirs = _both(dict(rows=2, cols=2, subplot_titles=["a", "b", "c", "d"], shared_xaxes=True), _calls)
    assert ours == theirs


def test_the_comparison_can_fail():
    """Negative controls: what differs is seen."""
    kw = dict(rows=2, cols=2, shared_xaxes=True)
    assert _json(subplots(**kw)) != _json(make_subplots(**{**kw, "shared_xaxes": False}))
    assert _json(subplots(**kw, horizontal_spacing=0.05)) != _json(make_subplots(**kw))
    a = Figure().add_trace(dict(type="heatmap", z=np.ones((2, 2)), colorscale="Viridis"))
    b = go.Figure(go.Heatmap(z=np.ones((2, 2)), colorscale="Cividis"))
    assert _json(a) != _json(b)


def test_a_named_colorscale_is_expanded_and_a_list_kept():
    assert colorscale("Viridis")[0] == [0.0, "#440154"]
    assert colorscale([[0, "red"], [1, "blue"]]) == [[0, "red"], [1, "blue"]]
