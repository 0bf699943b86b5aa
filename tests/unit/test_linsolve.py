"""The fixed-pattern block LU (taichi_star.linsolve) against a dense NumPy solve."""

import numpy as np
import pytest
import taichi as ti

from taichi_star.physics import coupled_node_pairs
from taichi_star.geometry import build_topology
from taichi_star.linsolve import BlockSystem, minimum_degree_order, plan_elimination
from taichi_star.params import StarParams


@ti.kernel
def _factor_and_solve(system: ti.template()):
    for b in range(system.blocks.shape[0]):
        system.factor(b)
        system.solve(b)


def _random_system(pairs, n_nodes, rng):
    """A non-symmetric matrix on the node pattern, made block-diagonally dominant so that LU
    without pivoting is stable (as the Newton matrix is: M/h² plus a stiffness)."""
    matrix = np.zeros((2 * n_nodes, 2 * n_nodes))
    for i, j in pairs:
        matrix[2 * i:2 * i + 2, 2 * j:2 * j + 2] = rng.standard_normal((2, 2))
        matrix[2 * j:2 * j + 2, 2 * i:2 * i + 2] = rng.standard_normal((2, 2))
    matrix += np.diag(np.abs(matrix).sum(axis=1) + 1.0)
    return matrix


def _load_blocks(plan, matrix):
    blocks = np.zeros((plan.n_slots, 2, 2))
    for (i, j), slot in plan.slot.items():
        blocks[slot] = matrix[2 * i:2 * i + 2, 2 * j:2 * j + 2]
    return blocks


@pytest.mark.parametrize("n_arc", [2, 18])
def test_block_lu_matches_dense_solve(taichi_cpu, n_arc):
    topology = build_topology(StarParams(n_arc=n_arc, n_limb=3))
    pairs = coupled_node_pairs(topology)
    plan = plan_elimination(topology.n_nodes, pairs)
    rng = np.random.default_rng(n_arc)
    batch = 3
    matrices = [_random_system(pairs, topology.n_nodes, rng) for _ in range(batch)]
    rhs = rng.standard_normal((batch, topology.n_nodes, 2))
    system = BlockSystem(plan, batch)
    system.blocks.from_numpy(np.stack([_load_blocks(plan, m) for m in matrices]))
    system.rhs.from_numpy(rhs)
    _factor_and_solve(system)
    solution = system.rhs.to_numpy()
    for b in range(batch):
        expected = np.linalg.solve(matrices[b], rhs[b].ravel())
        # well-conditioned (diagonally dominant) systems: LU error is a few ulps × condition
        np.testing.assert_allclose(solution[b].ravel(), expected, rtol=0, atol=1e-12)


def test_minimum_degree_eliminates_chains_without_fill():
    """A path graph has no fill under minimum degree: the plan stores exactly its pattern."""
    n = 12
    pairs = [(i, i + 1) for i in range(n - 1)]
    plan = plan_elimination(n, pairs)
    assert plan.n_slots == plan.n_structural == n + 2 * len(pairs)
    assert sorted(minimum_degree_order(n, pairs)) == list(range(n))


def test_the_patterns_slots_come_before_the_fill_ins():
    """The star's pattern (its diagonal and coupled pairs, both ways) holds exactly the slots
    below `n_structural`; every later slot is fill-in, written only by the factorisation (the
    lanes' copy zeroes those without reading them)."""
    topology = build_topology(StarParams())
    pairs = coupled_node_pairs(topology)
    plan = plan_elimination(topology.n_nodes, pairs)
    pattern = ({(n, n) for n in range(topology.n_nodes)}
               | {(int(i), int(j)) for i, j in pairs} | {(int(j), int(i)) for i, j in pairs})
    structural = {pair for pair, slot in plan.slot.items() if slot < plan.n_structural}
    assert structural == pattern == set(plan.pattern_slot)
    assert all(plan.pattern_slot[pair] == plan.slot[pair] for pair in pattern)
    assert plan.n_structural == len(pattern) < plan.n_slots  # the star's elimination fills in


def test_plan_is_cheaper_than_a_bordered_band():
    """The default star's factorisation costs less than a bordered band (node
    half-bandwidth 9 under RCM, 19 DOFs: 2 flops × 2N DOFs × 19² ≈ 0.28 MFLOP)."""
    topology = build_topology(StarParams())
    plan = plan_elimination(topology.n_nodes, coupled_node_pairs(topology))
    band_flops = 2 * (2 * topology.n_nodes) * (2 * 9 + 1) ** 2
    assert plan.factor_flops < band_flops / 3


def test_every_engine_of_a_topology_eliminates_in_one_order():
    """An instance's pivots must not depend on the switches of the other instances of its
    batch: the jet's "spread" couples each space's corners (more blocks), but every term set
    and configuration of a topology eliminates in the order of the default pattern (the
    spread's own minimum-degree order moved the other instances of its batch by ~1e-13)."""
    from taichi_star.engine import elimination_plan
    from taichi_star.model import build_model

    base = StarParams()
    variants = [base, base.replace(jet_application="spread"), base.replace(damping_time=1e-3),
                base.replace(wake_coupling=1.0, linear_drag=2.0, jet_direction="normal")]
    plans = [elimination_plan(model.topology, model.terms_used)
             for model in (build_model([p]) for p in variants)]
    topology = build_topology(base)
    default_order = minimum_degree_order(topology.n_nodes, coupled_node_pairs(topology))
    for plan in plans:
        assert np.array_equal(plan.order, default_order)
    # the spread's corner blocks are there, under the same order
    assert set(plans[1].slot) > set(plans[0].slot)
