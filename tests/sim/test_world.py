"""The procedural ISS: walls enclose exactly the grown keep-in boxes, hatches open, distance query."""
import numpy as np
import pytest

from astrobee import config
from astrobee_sim.world import World, subtract_box


def test_subtract_box_volume():
    a = np.array([0, 0, 0, 2, 2, 2.0])
    b = np.array([1, 1, 1, 3, 3, 3.0])
    pieces = subtract_box(a, b)
    vol = sum(np.prod(p[3:] - p[:3]) for p in pieces)
    assert np.isclose(vol, 8 - 1)


def test_walls_enclose_free_space_without_overlap():
    w = World.from_config(thickness=0.05)
    rng = np.random.default_rng(0)
    # points just outside each face of each free box: either free (a hatch) or inside a wall
    pts = []
    for b in w.free:
        for _ in range(150):
            ax, side = rng.integers(3), rng.integers(2)
            p = rng.uniform(b[:3], b[3:])
            p[ax] = b[3 + ax] + 0.01 if side else b[ax] - 0.01
            pts.append(p)
    P = np.array(pts)
    free = w.in_free_space(P)
    in_wall = np.zeros(len(P), bool)
    for s in w.walls:
        in_wall |= np.all((P >= s[:3]) & (P <= s[3:]), axis=1)
    assert np.all(free | in_wall), "a gap in the walls"
    assert not np.any(free & in_wall), "a wall inside the free space"
    assert np.all(w.wall_distance(P[in_wall & ~free]) < 0)


def test_hatch_passages_are_open():
    w = World.from_config()
    for a, b in (("node_2", "jem"), ("node_2", "eu_lab"), ("node_1", "node_3")):
        pa, pb = config.waypoint(a), config.waypoint(b)
        # straight segment between the two module waypoints lies in free space for these pairs
        seg = pa + np.linspace(0, 1, 200)[:, None] * (pb - pa)
        assert w.in_free_space(seg).all(), (a, b)
        assert (w.wall_distance(seg) > 0).all()


def test_wall_distance_matches_box_geometry():
    w = World.from_config()
    c = config.waypoint("jem")
    box = w.free[6]                     # the JEM's main box
    assert np.all(c > box[:3]) and np.all(c < box[3:])
    expect = min(np.min(c - box[:3]), np.min(box[3:] - c))
    assert abs(w.wall_distance(c)[0] - expect) < 1e-9
    assert not w.in_free_space([[0.0, 50.0, 0.0]])[0]


def test_pruned_queries_match_brute_force():
    w = World.from_config(thickness=0.25)
    rng = np.random.default_rng(3)
    lo, hi = w.free[:, :3].min(axis=0), w.free[:, 3:].max(axis=0)
    for _ in range(200):
        pts = rng.uniform(lo, hi) + rng.normal(0, rng.uniform(0.01, 1.0), (40, 3))
        brute = w._box_sdf(pts, w.walls).min(axis=1)
        assert np.allclose(w.wall_distance(pts), brute)
        d, i = w.nearest(pts)
        assert np.isclose(d, brute.min()) and np.isclose(brute[i], d)


def test_cell_cached_queries_are_exact_for_robots_bags_and_node_clouds():
    """The grid of candidate slabs never drops a point's nearest slab: single points (robots,
    0.1 m cells), box corners and FEM-sized clouds (0.25 m cells) near walls and in hatches give
    exactly the brute-force distance over all ~400 slabs, repeated queries (cached) too."""
    w = World.from_config(thickness=0.25)
    rng = np.random.default_rng(11)
    for _ in range(300):
        box = w.free[rng.integers(len(w.free))]
        centre = box[:3] + rng.random(3) * (box[3:] - box[:3])
        n = int(rng.choice([1, 8, 412]))
        pts = centre + (rng.random((n, 3)) - 0.5) * rng.choice([0.0, 0.6, 3.0])
        brute = w._box_sdf(pts, w.walls).min(axis=1)
        for _ in range(2):
            assert np.array_equal(w.wall_distance(pts), brute)
            d, i = w.nearest(pts)
            assert d == brute.min() and brute[i] == d


def _slab_rays(w: World) -> tuple[list, list]:
    """A ray through the middle of every slab across its thin axis."""
    lo, hi = w.walls[:, :3], w.walls[:, 3:]
    mid = (lo + hi) / 2
    thin = np.argmin(hi - lo, axis=1)
    starts, ends = mid.copy(), mid.copy()
    k = np.arange(len(mid))
    starts[k, thin] = lo[k, thin] - 0.01
    ends[k, thin] = hi[k, thin] + 0.01
    return starts.tolist(), ends.tolist()


@pytest.mark.parametrize("per_body,visuals", [(1, True), (1, False), (16, False), (64, False)])
def test_build_pybullet_keeps_every_slab(per_body, visuals):
    """Every slab is in the pybullet world, whatever the grouping: pybullet keeps only the first
    16 children of a compound shape, and 64 a body once lost 233 of 426 slabs (a robot flew
    out through Node 2's ceiling)."""
    import pybullet as p
    from astrobee_sim.world import MAX_COMPOUND_CHILDREN, build_pybullet
    w = World.from_config(thickness=0.25)
    c = p.connect(p.DIRECT)
    try:
        ids = build_pybullet(w, c, visuals=visuals, per_body=per_body)
        group = 1 if per_body <= 1 or visuals else min(per_body, MAX_COMPOUND_CHILDREN)
        assert len(ids) == -(-len(w.walls) // group)
        starts, ends = _slab_rays(w)
        hits = [h[0] for h in p.rayTestBatch(starts, ends, physicsClientId=c)]
        missing = [k for k, h in enumerate(hits) if h not in ids]
        assert not missing, f"{len(missing)} of {len(w.walls)} slabs missing: {missing[:10]}"
        # a ray up across Node 2 stops at the wall just outside the grown keep-in box
        hit = p.rayTest([10.95, 0.0, 4.84], [10.95, 0.0, 10.0], physicsClientId=c)[0]
        assert hit[0] in ids
        assert abs(hit[3][2] - w.free[16, 5]) < 1e-6
    finally:
        p.disconnect(c)


def test_robot_pushed_up_in_node2_meets_the_ceiling():
    """The default (compound-walled) simulation: full thrust up from Node 2 ends on its ceiling."""
    import pybullet as p
    from astrobee_sim.simulation import Simulation
    with Simulation("node2_to_jem") as sim:
        p.resetBasePositionAndOrientation(sim.robots[""].id, [10.95, 0.6, 4.84], [0, 0, 0, 1],
                                          physicsClientId=sim.client)
        touched = False
        for _ in range(40):
            sim.command(np.array([0.0, 0.0, 2.0, 0.0, 0.0, 0.0]))
            sim.advance(0.5)
            touched = touched or bool(sim.contacts())
        z = sim.robot_state()[0][2]
    assert touched
    assert z < 6.5, z
