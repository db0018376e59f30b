"""The fast least distance solvers (Goldfarb-Idnani, NumPy and compiled) against the plain one (one NNLS)."""

import numpy as np
import pytest

from tonguevis.sim.least_distance import least_distance, least_distance_from


def _growing_problem(rng, width, blocks, rows):
    """Blocks of rows g z >= h for one problem, feasible (a point x satisfies them all) and growing as the
    projection's passes do: each block linearised about a point near the last, some rows near-duplicates of
    earlier ones (the same node a pass later)."""
    x = rng.normal(0, 1.0, width)
    out = []
    earlier = np.zeros((0, width))
    for _ in range(blocks):
        g = rng.normal(size=(rows, width))
        if len(earlier):  # a few near-duplicates of earlier rows
            pick = rng.choice(len(earlier), size=rows // 4, replace=False)
            g[: rows // 4] = earlier[pick] + rng.normal(0, 1e-3, (rows // 4, width))
        h = g @ x - rng.uniform(0.0, 0.3, rows)  # x feasible, the origin mostly not
        out.append((g, h))
        earlier = np.vstack([earlier, g])
    return out


def test_goldfarb_idnani_from_each_earlier_answer_equals_the_nnls():
    """Started from the answer of the rows before (as a pass starts from the last), each growing problem's z is
    the NNLS's to rounding; an infeasible one is given back (None) or answered as the NNLS does."""
    rng = np.random.default_rng(7)
    solved = 0
    for _ in range(20):
        blocks = _growing_problem(rng, 12, 4, 15)
        g, h = np.zeros((0, 12)), np.zeros(0)
        active, weights = np.zeros(0, dtype=np.int64), np.zeros(0)
        for g_new, h_new in blocks:
            g, h = np.vstack([g, g_new]), np.concatenate([h, h_new])
            ref = least_distance(g, h)
            found = least_distance_from(g, h, active, weights)
            assert found is not None
            z, active, weights = found
            np.testing.assert_allclose(z, ref, atol=1e-9 * np.abs(ref).max())
            assert np.all(weights >= 0) and len(active) >= 2
            solved += 1
    assert solved == 80
    # z >= 1 and z <= 0: no z (the multiplier to release is missing: given back)
    assert least_distance_from(np.array([[1.0], [-1.0]]), np.array([1.0, 0.0]), np.zeros(0, int), np.zeros(0)) is None


@pytest.mark.parametrize("threads", [False, True])
def test_the_compiled_batch_equals_the_nnls_pass_after_pass(threads, monkeypatch):
    """LeastDistanceBatch: 12 problems growing by blocks, all solved in one call a block (one launch, or split
    over threads: a width of its own, so its first call builds the kernel, in one launch before any split),
    each started from its answer of the block before: every z the NNLS's to rounding; an infeasible problem
    is given back (False) and the next call starts it afresh."""
    from tonguevis.sim import least_distance_kernel
    from tonguevis.sim.least_distance_kernel import LeastDistanceBatch

    if threads:
        monkeypatch.setattr(least_distance_kernel, "PARALLEL_PROBLEMS", 4)
        monkeypatch.setattr(least_distance_kernel.os, "cpu_count", lambda: 4)
    width = 21 if threads else 20

    rng = np.random.default_rng(11)
    n = 12
    problems = [_growing_problem(rng, width, 4, 30) for _ in range(n)]
    # slot 5: a contradiction from the third block on (g z >= 1 and -g z >= 0 for one direction)
    e = np.zeros(width)
    e[0] = 1.0
    g3, h3 = problems[5][2]
    problems[5][2] = (np.vstack([g3, e, -e]), np.concatenate([h3, [1.0, 0.0]]))
    batch = LeastDistanceBatch(n, width, 4)
    order = np.array([3, 0, 7, 1, 2, 4, 5, 6, 8, 9, 10, 11])  # slots need not come in order
    for block in range(4):
        g = np.vstack([problems[i][block][0] for i in order])
        h = np.concatenate([problems[i][block][1] for i in order])
        first = np.concatenate([[0], np.cumsum([len(problems[i][block][1]) for i in order])])
        batch.add(order, g, h, first)
        solved = batch.solve(order)
        for j, i in enumerate(order):
            g_all = np.vstack([problems[i][b][0] for b in range(block + 1)])
            h_all = np.concatenate([problems[i][b][1] for b in range(block + 1)])
            got_g, got_h = batch.problem(i)
            np.testing.assert_array_equal(got_g, g_all)
            np.testing.assert_array_equal(got_h, h_all)
            ref = least_distance(g_all, h_all)
            if i == 5 and block >= 2:
                assert ref is None and not solved[j] and batch.count[i] == 0
                continue
            assert solved[j]
            np.testing.assert_allclose(batch.z[i], ref, atol=1e-9 * np.abs(ref).max())
            assert batch.count[i] >= 2 and np.all(batch.weights[i, :batch.count[i]] >= 0)
