"""The SimBackend seam: both backends satisfy the protocol, validate a reset before they touch
the world, and the rigid backend's physics (force clip, watchdog, carried bag) is right."""
import numpy as np
import pytest

from astrobee import config, flight_modes
from astrobee.scenario import Scenario, ScenarioError
from astrobee_sim.backend import SimBackend, make_backend
from astrobee_sim.rigid_backend import RigidSim

BAD_RESETS = [("node2_to_jem", -1), ("../etc/passwd", 0), ("/etc/passwd", 0),
              ("no_such_scenario", 0), ("node2_to_jem", 1.5)]


@pytest.fixture(params=["pybullet", "rigid"])
def backend(request):
    b = make_backend(request.param, "node2_to_jem_bag", seed=3)
    yield b
    b.close()


def _snapshot(b):
    return (b.time, b.steps, b.seed, b.scenario, b.robot_names(),
            [np.concatenate(b.robot_state(n)) for n in b.robot_names()])


def test_both_backends_are_sim_backends(backend):
    assert isinstance(backend, SimBackend)
    assert isinstance(backend.scenario, Scenario) and backend.scenario.name == "node2_to_jem_bag"
    assert backend.robot_names() == [""] and backend.bag_info().model == "rigid"
    rc, bc = backend.clearance()
    assert rc > 0 and bc > 0 and not backend.contacts()


@pytest.mark.parametrize("scenario,seed", BAD_RESETS)
def test_bad_reset_is_refused_and_the_world_runs_on(backend, scenario, seed):
    backend.command([0.3, 0, 0, 0, 0, 0])
    backend.step(35)
    before = _snapshot(backend)
    with pytest.raises(ScenarioError):
        backend.reset(scenario, seed)
    after = _snapshot(backend)
    assert before[:5] == after[:5]
    assert all(np.array_equal(a, b) for a, b in zip(before[5], after[5]))
    backend.step(35)                               # still steps, from where it was
    assert backend.steps == before[1] + 35
    backend.reset("node2_to_jem", 0)               # and a good reset still works
    assert backend.scenario.name == "node2_to_jem" and backend.bag_info() is None


def test_scenario_with_robots_abc_is_refused_before_the_world_changes(tmp_path, monkeypatch):
    cfg = tmp_path / "config"
    import shutil
    shutil.copytree(config.config_dir(), cfg)
    (cfg / "scenarios" / "broken.yaml").write_text("robots: abc\n")
    monkeypatch.setenv("ASTROBEE_CONFIG_DIR", str(cfg))
    sim = RigidSim("node2_to_jem")
    with pytest.raises(ScenarioError, match="robots"):
        sim.reset("broken", 0)
    assert sim.robot_names() == [""] and sim.scenario.name == "node2_to_jem"


def test_rigid_force_is_clipped_to_the_flight_mode_and_moves_as_f_over_m():
    sim = RigidSim("node2_to_jem")          # yawed -90 deg: body +x is world -y
    p0 = sim.robot_state()[0]
    fmax = flight_modes.get("nominal").max_force[0]
    for _ in range(62):
        assert sim.command([5.0, 0, 0, 0, 0, 0])      # above the limit: clipped, not rejected
        sim.step(6)
    d = sim.robot_state()[0] - p0
    expect = 0.5 * fmax / float(config.astrobee()["mass"]) * sim.time ** 2
    assert d[1] == pytest.approx(-expect, rel=0.02) and abs(d[0]) < 1e-6 and abs(d[2]) < 1e-6
    assert not sim.command([np.nan, 0, 0, 0, 0, 0]) and not sim.command([1e7, 0, 0, 0, 0, 0])


def test_rigid_watchdog_zeroes_the_wrench():
    sim = RigidSim("node2_to_jem")
    sim.command([0.3, 0, 0, 0, 0, 0])
    sim.step(int(0.30 / sim.dt))
    assert not sim.faulted("")
    sim.step(int(0.05 / sim.dt))
    assert sim.faulted("")
    v = np.linalg.norm(sim.robot_state()[2])
    sim.step(350)
    assert np.linalg.norm(sim.robot_state()[2]) == pytest.approx(v, abs=1e-9)   # coasting
    sim.command([0.3, 0, 0, 0, 0, 0])
    sim.step(1)
    assert not sim.faulted("")


def test_rigid_bag_is_carried_as_extra_mass_where_pybullet_puts_it(make_sim):
    for variant in ("front", "right", "top"):
        rig = RigidSim("node2_to_jem_bag", bag_variant=variant)
        ref = make_sim("node2_to_jem_bag", bag_variant=variant)
        a, b = rig.bag_state(), ref.bag_state()
        assert np.allclose(a.position, b.position, atol=1e-3)
        assert abs(abs(float(np.dot(a.orientation, b.orientation))) - 1) < 1e-6
    # 10 kg more: the same (unclipped) force accelerates the pair ~2x slower than the robot
    alone, carrying = RigidSim("node2_to_jem"), RigidSim("node2_to_jem_bag")
    for s in (alone, carrying):
        s.command([0.3, 0, 0, 0, 0, 0])
        s.step(350)
    v1, v2 = np.linalg.norm(alone.robot_state()[2]), np.linalg.norm(carrying.robot_state()[2])
    m = float(config.astrobee()["mass"])
    assert v2 / v1 == pytest.approx(m / (m + 10.0), rel=0.05)
    assert carrying.bag_points().shape == (8, 3)
