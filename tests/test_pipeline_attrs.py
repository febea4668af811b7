"""Store attributes as netCDF takes them (issue 34): ``pipeline._attrs`` encodes the Python
view (nested record, {code: meaning} flags, label lists) and decodes it back, from either store
format; what it writes is what netCDF takes (``netcdf_problems``, written from netCDF's rules)."""

from __future__ import annotations

import json

import numpy as np
import pytest

from pipeline._attrs import decode_attrs, encode_attrs, read_record, record_text
from pipeline_cases import _netcdf_attr_problem

VIEW = {
    "long_name": "solver status",
    "units": "1",
    "spacing": "log2",
    "scale": 0.5,
    "count": 3,
    "bounds": [1.0, 2.5],
    "flag_meanings": {"-1": "not computed yet", "0": "converged: error below rtol",
                      "8": "converged, but U out of range", "2": "NaN; or inf"},
    "labels": ["march (adaptive)", "periodic"],
    "names": ["A0", "A1", "B1"],
    "sets": [[1.0, 2.0], [3.0]],
}


def test_the_python_view_survives_encoding():
    stored = encode_attrs(VIEW, np.dtype(np.int8))
    assert decode_attrs(stored) == VIEW
    assert all(_netcdf_attr_problem(v) is None for v in stored.values()), stored
    # CF flags: codes sorted, one blank-free word each (repeated first clauses made unique)
    assert stored["flag_values"] == [-1, 0, 2, 8]
    assert stored["flag_meanings"] == "not_computed_yet converged nan converged_8"
    assert json.loads(stored["flag_descriptions"])[3] == "converged, but U out of range"
    assert stored["labels"] == '["march (adaptive)", "periodic"]'


def test_a_format_1_view_decodes_to_itself_and_the_record_reads_from_both():
    record = {"format_version": 1, "provenance": {"scene_hash": "abc", "engines": {"periodic": "3.1"}},
              "state": {"skeleton_complete": True}, "run": {"wall_seconds": float("nan")}}
    assert decode_attrs(VIEW) == VIEW
    assert read_record({"pipeline": record}) is record
    back = read_record({"pipeline": record_text(record)})
    assert back["provenance"] == record["provenance"] and np.isnan(back["run"]["wall_seconds"])
    assert read_record({"something": 1}) is None and read_record({"pipeline": "not json"}) is None


def test_values_netcdf_refuses_are_refused_by_name():
    for bad in ({"a": 1}, True, None, [], ["a", "b"], [True, False], [[1, 2]], np.bool_(True)):
        with pytest.raises(TypeError, match="attribute 'extra'"):
            encode_attrs({"long_name": "x", "extra": bad})
        assert _netcdf_attr_problem(bad) is not None  # the test's own check agrees


def test_a_float_array_without_units_is_refused(tmp_path):
    from pipeline._store import create_array, open_group

    g = open_group(tmp_path / "s.zarr", "w")
    with pytest.raises(ValueError, match="'U'.*units"):
        create_array(g, "U", shape=(2,), chunks=(2,), dtype=np.float64, fill=np.nan, dims=("x",),
                     attrs={"long_name": "speed"})
    create_array(g, "n", shape=(2,), chunks=(2,), dtype=np.int32, fill=0, dims=("x",), attrs={"long_name": "count"})
