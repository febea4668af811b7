"""A store's attributes as netCDF and CF take them: written and read here only (issue 34).

Since store format 2 every attribute a store holds is a string, a number or a non-empty 1-D
list of numbers, so ``xarray.open_zarr(store).to_netcdf(path)`` works as it is (scipy's
netCDF 3 writer included).  The code of the pipeline and of the reports works with the
*Python view* of the attributes, the nested values format 1 stored as they were:

=====================  ===========================================  ==================================
attribute              Python view                                  stored (format 2)
=====================  ===========================================  ==================================
``pipeline`` (root)    dict: format_version, kind, provenance,      JSON text of the dict
                       layout, state, run record
``flag_meanings``      {code (str): sentence}                       CF: ``flag_values`` (the codes, in
                                                                    the variable's dtype),
                                                                    ``flag_meanings`` (one word per
                                                                    code, blank-separated) and
                                                                    ``flag_descriptions`` (JSON text:
                                                                    the sentences, in code order)
``labels``, ``names``,  list (of strings; ``sets``: of lists)       JSON text
``sets``
anything else          string, number, 1-D list of numbers          the same
=====================  ===========================================  ==================================

:func:`encode_attrs` turns a Python view into what is stored and refuses any other value
(a dict, a bool, None, a list of strings under another key) naming the attribute, so a new
kind's schema cannot write an attribute netCDF refuses.  :func:`decode_attrs` turns stored
attributes of either format (or of the netCDF file written from a store) back into the Python
view; :func:`read_record` is the ``pipeline`` record of a group's attributes.
"""

from __future__ import annotations

import json
import re
from numbers import Integral, Real

import numpy as np

__all__ = ["ATTRS_KEY", "JSON_KEYS", "decode_attrs", "encode_attrs", "read_record", "record_text"]

#: the root attribute holding the pipeline's record
ATTRS_KEY = "pipeline"
#: attributes stored as JSON text (their Python view is a dict or a list)
JSON_KEYS = (ATTRS_KEY, "labels", "names", "sets")
_FLAG_KEYS = ("flag_values", "flag_meanings", "flag_descriptions")


def _word(meaning: str, code: str) -> str:
    """One blank-free word for a flag meaning: its first clause, lower case, words joined by _."""
    head = re.split(r"[:;,(]", str(meaning), maxsplit=1)[0].strip().lower()
    word = re.sub(r"[^a-z0-9]+", "_", head).strip("_")
    return word or f"code_{code}".replace("-", "minus_")


def _is_number(v) -> bool:
    return isinstance(v, (Integral, Real)) and not isinstance(v, (bool, np.bool_))


def _scalar(v):
    """A numpy scalar as the Python number it holds; anything else unchanged."""
    return v.item() if isinstance(v, np.generic) else v


def _flag_table(table: dict, dtype) -> dict:
    codes = sorted(table, key=int)
    words, seen = [], set()
    for c in codes:
        w = _word(table[c], c)
        w = w if w not in seen else f"{w}_{c}".replace("-", "minus_")
        seen.add(w)
        words.append(w)
    values = np.asarray([int(c) for c in codes], dtype=dtype if dtype is not None else np.int32)
    return {"flag_values": [int(v) for v in values],  # a list: zarr writes JSON
            "flag_meanings": " ".join(words),
            "flag_descriptions": json.dumps([str(table[c]) for c in codes])}


def encode_attrs(attrs: dict, dtype=None) -> dict:
    """The attributes to store for the Python view ``attrs`` (module docstring); ``dtype``:
    the variable's, which CF's ``flag_values`` take.

    Raises ``TypeError`` naming an attribute whose value netCDF refuses and that is not one of
    :data:`JSON_KEYS` (a dict, a bool, None, a list that is not all numbers, an empty list).
    """
    out = {}
    for key, value in attrs.items():
        if key == "flag_meanings" and isinstance(value, dict):
            out.update(_flag_table(value, dtype))
        elif key in JSON_KEYS:
            out[key] = json.dumps(value, allow_nan=True)
        elif isinstance(value, str) or _is_number(value):
            out[key] = _scalar(value)
        elif (isinstance(value, (list, tuple, np.ndarray)) and np.ndim(value) == 1 and len(value) > 0
              and all(_is_number(v) for v in value)):
            out[key] = [_scalar(v) for v in value]
        else:
            raise TypeError(f"attribute {key!r} = {value!r:.80}: netCDF takes strings, numbers and non-empty "
                            f"1-D lists of numbers (a record or a list of words goes under one of {JSON_KEYS}, "
                            "as JSON text)")
    return out


def decode_attrs(attrs: dict) -> dict:
    """The Python view of stored attributes ``attrs``: those of a format-2 store, of a format-1
    store (already the Python view) or of the netCDF file written from a store."""
    out = {}
    for key, value in attrs.items():
        if key in JSON_KEYS and isinstance(value, str):
            try:
                value = json.loads(value)
            except ValueError:
                pass
        elif isinstance(value, np.ndarray):
            value = [_scalar(v) for v in value.ravel()] if value.ndim else _scalar(value)
        out[key] = _scalar(value)
    if "flag_values" in out and isinstance(out.get("flag_meanings"), str):
        codes = [int(v) for v in np.atleast_1d(out.pop("flag_values"))]
        words = out.pop("flag_meanings").split()
        sentences = out.pop("flag_descriptions", None)
        try:
            sentences = json.loads(sentences) if isinstance(sentences, str) else None
        except ValueError:
            sentences = None
        if not (isinstance(sentences, list) and len(sentences) == len(codes)):
            sentences = words if len(words) == len(codes) else [str(c) for c in codes]
        out["flag_meanings"] = {str(c): str(s) for c, s in zip(codes, sentences)}
    return out


def read_record(attrs: dict) -> dict | None:
    """The ``pipeline`` record (format_version, provenance, layout, state, run) of a store
    group's attributes ``attrs`` (either format, or a netCDF file's), or None where there is
    none (not a pipeline store)."""
    value = decode_attrs({ATTRS_KEY: attrs[ATTRS_KEY]}).get(ATTRS_KEY) if ATTRS_KEY in attrs else None
    return value if isinstance(value, dict) else None


def record_text(record: dict) -> str:
    """The stored form of the ``pipeline`` record ``record``."""
    return encode_attrs({ATTRS_KEY: record})[ATTRS_KEY]
