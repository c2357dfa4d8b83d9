"""Argument checks shared by the public API (loads, constraints, shapes, rods, scenes).

Each helper takes the value, the name it is shown under (``"der.end_force: force"``) and returns the value
converted (a float, an int, a float array); anything else raises, before any work, a ``TypeError`` (wrong kind
of value: a string, None, a complex number) or a ``ValueError`` (right kind, wrong value: shape, range, NaN),
whose message names the argument, shows what it got and says what is allowed.
"""
import numbers

import numpy as np


def _show(value, limit=80):
    """A short description of ``value`` for an error message."""
    if isinstance(value, np.ndarray):
        small = f" ({np.array2string(value, threshold=6)})" if value.size <= 6 else ""
        return f"an array of shape {value.shape}{small}"
    text = repr(value)
    if len(text) > limit:
        text = text[:limit - 3] + "..."
    return f"{text} ({type(value).__name__})" if not isinstance(value, (int, float)) or isinstance(value, bool) \
        else text


def _is_real_scalar(value):
    return (isinstance(value, (numbers.Real, np.floating, np.integer))
            and not isinstance(value, (bool, np.bool_)))


def real_number(value, name, allowed="a real number"):
    """``value`` as a float; TypeError for a non-number (str, None, bool, complex, array), ValueError for NaN/inf."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if not _is_real_scalar(value):
        hint = " (complex numbers are not allowed)" if isinstance(value, (complex, np.complexfloating)) else ""
        raise TypeError(f"{name} must be {allowed}; got {_show(value)}{hint}")
    v = float(value)
    if not np.isfinite(v):
        raise ValueError(f"{name} must be {allowed}, finite; got {value!r}")
    return v


def finite_number(value, name):
    """A finite real number (float)."""
    return real_number(value, name, "a finite real number")


def positive_number(value, name, allowed="a finite number > 0"):
    """A finite real number > 0 (float)."""
    v = real_number(value, name, allowed)
    if not v > 0:
        raise ValueError(f"{name} must be {allowed}; got {value!r}")
    return v


def integer(value, name, allowed="an integer"):
    """An integer (int): Python or numpy integers, and floats with an integral value (2.0, not 2.5)."""
    if isinstance(value, np.ndarray) and value.ndim == 0:
        value = value[()]
    if isinstance(value, (bool, np.bool_)) or not _is_real_scalar(value):
        raise TypeError(f"{name} must be {allowed}; got {_show(value)}")
    if isinstance(value, (numbers.Integral, np.integer)):
        return int(value)
    if not (np.isfinite(value) and float(value).is_integer()):
        raise ValueError(f"{name} must be {allowed}; got {value!r}, which is not a whole number "
                         f"(it would not be rounded silently)")
    return int(value)


def finite_array(value, name, shape=None, allowed=None, finite=True):
    """``value`` as a float array of ``shape`` (None for any; -1 in a dimension for any length).

    ``finite=False`` leaves NaN and inf entries to the caller (who can say which node is bad).

    TypeError for something that is not an array of real numbers (None, strings, complex), ValueError for a
    wrong shape or a NaN/inf entry.
    """
    want = _shape_text(shape) if allowed is None else allowed
    if value is None or isinstance(value, (str, bytes, dict, set)):
        raise TypeError(f"{name} must be {want}; got {_show(value)}")
    try:
        raw = np.asarray(value)
    except Exception as exc:   # ragged nested lists and the like
        raise TypeError(f"{name} must be {want}; got {_show(value)} ({exc})") from None
    if raw.dtype == object:
        raise TypeError(f"{name} must be {want}; got {_show(value)}")
    if np.iscomplexobj(raw):
        raise TypeError(f"{name} must be {want} of real numbers; got {_show(value)} (complex numbers are not allowed)")
    if raw.dtype.kind not in "biuf":
        raise TypeError(f"{name} must be {want}; got {_show(value)} (dtype {raw.dtype})")
    arr = raw.astype(float)
    if shape is not None:
        ok = arr.ndim == len(shape) and all(s == -1 or s == a for s, a in zip(shape, arr.shape))
        if not ok:
            raise ValueError(f"{name} must be {want}; got shape {arr.shape}" + (
                f": {_show(value)}" if arr.size <= 6 else ""))
    if finite and not np.isfinite(arr).all():
        bad = np.argwhere(~np.isfinite(arr))[0]
        raise ValueError(f"{name} must be {want}, every entry finite; entry {tuple(int(i) for i in bad)} is "
                         f"{arr[tuple(bad)]}")
    return arr


def vector3(value, name):
    """A finite 3-vector (float array of shape (3,))."""
    return finite_array(value, name, (3,), "a finite 3-vector [x, y, z]")


def _shape_text(shape):
    if shape is None:
        return "an array of finite real numbers"
    dims = ", ".join("any" if s == -1 else str(s) for s in shape)
    return f"a finite array of shape ({dims}{',' if len(shape) == 1 else ''})"
