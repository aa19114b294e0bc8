"""Scene building (taichi_sph/scene.py) outside the solvers."""

import numpy as np
import pytest

from taichi_sph import scene


@pytest.mark.parametrize("dim", [2, 3])
def test_overlap_mask_is_the_same_by_pairs_and_by_k_d_tree(monkeypatch, dim):
    """`remove_overlaps` compares small point sets pair by pair and larger ones with scipy's k-d tree
    (BRUTE_FORCE_PAIRS): both give the mask of the points farther than `dist` from every point of the
    other set, also where lattice points of the two sets lie `dist` apart to round-off. The shipped
    configs' scenes are the same either way
    (every short run bit for bit, tools/behaviour_check.py)."""
    rng = np.random.default_rng(7)
    dx = 0.01
    keep = np.round(rng.uniform(0.0, 0.3, (800, dim)) / dx) * dx
    others = np.round(rng.uniform(0.0, 0.3, (300, dim)) / dx) * dx
    others[::2, 0] += 0.5 * dx  # half the others half a spacing off the lattice: ties at dist = dx / 2
    random = rng.uniform(0.0, 0.3, (500, dim))
    for a, b, dist in ((keep, others, 0.5 * dx), (random, others, 0.01), (keep, random, 0.02)):
        exact = np.sqrt(((a[:, None, :] - b[None, :, :]) ** 2).sum(axis=-1)).min(axis=1) > dist
        monkeypatch.setattr(scene, "BRUTE_FORCE_PAIRS", len(a) * len(b))
        by_pairs = scene.remove_overlaps(a, b, dist)
        monkeypatch.setattr(scene, "BRUTE_FORCE_PAIRS", 0)
        by_tree = scene.remove_overlaps(a, b, dist)
        np.testing.assert_array_equal(by_pairs, exact)
        np.testing.assert_array_equal(by_tree, exact)
        assert 0 < exact.sum() < len(a)  # some points kept and some taken away: the masks mean something
