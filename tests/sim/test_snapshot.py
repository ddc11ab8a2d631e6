"""Snapshot/restore of the whole world, FEM nodes included; measured errors printed."""
import numpy as np
import pybullet as p
import pytest

from astrobee_sim.bags import MODELS


def full_state(sim):
    """Every body's base pose and velocity, every joint, every FEM node."""
    c = sim.client
    out = []
    for b in range(p.getNumBodies(physicsClientId=c)):
        bid = p.getBodyUniqueId(b, physicsClientId=c)
        if sim.bag is not None and sim.bag.model == "fem" and bid == sim.bag.id:
            continue
        pos, q = p.getBasePositionAndOrientation(bid, physicsClientId=c)
        v, w = p.getBaseVelocity(bid, physicsClientId=c)
        out += [*pos, *q, *v, *w]
        for j in range(p.getNumJoints(bid, physicsClientId=c)):
            out += list(p.getJointState(bid, j, physicsClientId=c)[:2])
    nodes = sim.bag.nodes() if sim.bag is not None and sim.bag.model == "fem" else np.zeros((0, 3))
    return np.array(out), nodes


def drive(sim, ticks):
    for k in range(ticks):
        sim.command([0.5, 0.1 * np.sin(k / 10), -0.1, 0, 0, 0.01])
        sim.step(6)


@pytest.mark.parametrize("model", MODELS)
def test_snapshot_restore(make_sim, model):
    # fem here is Bullet's soft body (its restore limits are what this test states); the fast
    # solver's bit-identical restore is tested in test_fem_fast.py
    sim = make_sim("node2_to_jem_bag", bag_model=model, bag_resolution=200,
                   fem_solver="bullet" if model == "fem" else None)
    drive(sim, 60)
    rigid0, nodes0 = full_state(sim)
    bag0 = sim.bag.state()
    snap = sim.snapshot()
    drive(sim, 40)
    rigid1, nodes1 = full_state(sim)
    assert np.abs(rigid1 - rigid0).max() > 1e-3                   # it did move on
    sim.restore(snap)
    rigid_r, nodes_r = full_state(sim)
    err_rigid = np.abs(rigid_r - rigid0).max()
    err_nodes = np.abs(nodes_r - nodes0).max() if len(nodes0) else 0.0
    print(f"\n{model}: restore error rigid {err_rigid:.3g}, FEM nodes {err_nodes:.3g} m")
    assert err_rigid < 1e-9 and err_nodes < 1e-6
    if model == "fem":
        assert np.abs(nodes1 - nodes0).max() > 1e-3                # nodes had moved, came back
    st = sim.bag.state()
    assert np.allclose(st.position, bag0.position, atol=1e-9)
    assert np.allclose(st.velocity, bag0.velocity, atol=1e-9)
    # continuing after the restore: near exact for the rigid models (saveState does not hold
    # the constraint solver's warm-start impulses of maximal-coordinate bodies: 1e-8..3e-7 m);
    # for FEM the node velocities cannot be restored in pybullet 3.2.7 (they keep those of
    # the moment of the restore)
    drive(sim, 40)
    rigid2, nodes2 = full_state(sim)
    cont = np.abs(rigid2 - rigid1).max()
    cont_nodes = np.abs(nodes2 - nodes1).max() if len(nodes1) else 0.0
    print(f"{model}: 0.64 s continuation error rigid {cont:.3g}, FEM nodes {cont_nodes:.3g} m")
    if model == "fem":
        assert cont_nodes < 0.05
    else:
        assert cont < 1e-5
