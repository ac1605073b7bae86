"""result.json (mbs.app.results): bounds read back exactly (never narrowed), NaN refused."""
import json
import math
import struct

import numpy as np
import pytest

from mbs.app.results import (ResultError, bound_from_json, bound_to_json, read_result, result_boxes,
                         solution_to_dict, write_result)
from verified.arith.interval import Interval
from verified.solver import Solution

SPECIAL = [0.0, -0.0, 5e-324, -5e-324, 2.2250738585072009e-308, 2.2250738585072014e-308,
           1.7976931348615157e308, -1.7976931348615157e308, 0.1, 1 / 3, 2.0 ** -1074 * 12345,
           1e22, 1e23, 9007199254740993.0, math.pi, math.nextafter(1.0, 2.0), math.nextafter(1.0, 0.0)]


def _random_doubles(n, seed=0):
    rng = np.random.default_rng(seed)
    bits = rng.integers(0, 2 ** 63 - 1, n, dtype=np.int64) | (rng.integers(0, 2, n).astype(np.int64) << 63)
    x = bits.view(np.float64)
    return x[np.isfinite(x)]  # all exponents: subnormals, huge, tiny


def _fake_solution(lo, hi):
    """A Solution with one output whose boxes have the given bounds (B, n)."""
    box = Interval._from_bounds(np.asarray(lo, float), np.asarray(hi, float))
    h = Interval._from_bounds(box.lo.min(axis=0)[None], box.hi.max(axis=0)[None])
    return Solution(t=np.array([0.5]), boxes=[box], hull=h, tube_t=np.array([0.0, 0.5]), tube=[box],
                    tube_hull=h, t_reached=0.5, status="completed", reason="",
                    stats={"steps": 1, "wall_s": 0.01, "final_boxes": box.shape[0], "order": np.int64(12)})


def test_json_bounds_round_trip_exactly():
    xs = np.concatenate([np.array(SPECIAL), _random_doubles(20000)])
    text = json.dumps([bound_to_json(x) for x in xs], allow_nan=False)
    back = [bound_from_json(v) for v in json.loads(text)]
    for a, b in zip(xs, back):
        assert struct.pack("<d", a) == struct.pack("<d", b)  # same bits, sign of zero included
    # repr never needs more than 17 significant digits
    assert max(len(repr(float(x)).split("e")[0].replace("-", "").replace(".", "").lstrip("0")) for x in xs) <= 17


def test_result_file_round_trip(tmp_path):
    x = _random_doubles(400, seed=1)[:400]
    x = x[: (x.size // 4) * 4].reshape(-1, 2, 2)  # (B, n=2, [a, b])
    lo, hi = np.minimum(x[..., 0], x[..., 1]), np.maximum(x[..., 0], x[..., 1])
    lo[0, 0], hi[0, 0] = 5e-324, 1.7976931348615157e308
    sol = _fake_solution(lo, hi)
    p = write_result(tmp_path / "out" / "result.json", sol, scene="s.toml", mode="i", state_names=["q", "qd"],
                     t_end=0.5)
    data = read_result(p)
    assert set(data) == {"scene", "mode", "state_names", "t_end", "t_reached", "status", "reason", "method",
                         "method_log", "outputs", "stats"}
    assert data["status"] == "completed" and data["state_names"] == ["q", "qd"]
    assert {"wall_s", "steps", "max_boxes", "pruned_boxes"} <= set(data["stats"])
    back = result_boxes(data, 0)
    assert np.array_equal(back.lo, lo) and np.array_equal(back.hi, hi)
    hull = np.array(data["outputs"][0]["hull"])
    assert np.array_equal(hull[:, 0], lo.min(axis=0)) and np.array_equal(hull[:, 1], hi.max(axis=0))
    # the file is strict JSON (no NaN/Infinity tokens)
    json.loads(p.read_text(), parse_constant=lambda c: pytest.fail(f"non-standard constant {c}"))


def test_infinite_bounds_are_strings_and_nan_is_refused(tmp_path):
    sol = _fake_solution([[-np.inf, 0.0]], [[1.0, np.inf]])
    data = read_result(write_result(tmp_path / "r.json", sol))
    assert data["outputs"][0]["boxes"][0] == [[-math.inf, 1.0], [0.0, math.inf]]
    assert '"-inf"' in (tmp_path / "r.json").read_text()
    with pytest.raises(ResultError, match="NaN"):
        solution_to_dict(_fake_solution([[np.nan, 0.0]], [[1.0, 1.0]]))
    with pytest.raises(ResultError):
        bound_from_json("nan")
