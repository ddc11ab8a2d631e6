"""Realism knobs (astrobee.realism + astrobee_sim.realism_effects): off changes nothing; EKF noise
and bias statistics; determinism per seed; propulsion lag; disturbance impulses; the told mass;
bad values; snapshot/restore; and the told mass through sim_node (graph)."""
import subprocess
import sys

import numpy as np
import pytest

from astrobee import rotations as rot
from astrobee.realism import Disturbance, Realism, presets, resolve
from astrobee.scenario import Scenario, ScenarioError
from astrobee_sim.realism_effects import RealismEffects

STATE = (np.array([10.0, -1.0, 4.8]), rot.normalize(np.array([0.1, -0.2, 0.3, 0.9])),
         np.array([0.05, -0.02, 0.0]), np.array([0.0, 0.01, -0.02]))


def _fly(sim, ticks=60, push=(0.2, -0.1, 0.05, 0.0, 0.01, -0.01)):
    """A short driven flight; the truth and EKF states each tick."""
    out = []
    for k in range(ticks):
        sim.command(np.array(push) * (1 if (k // 20) % 2 == 0 else -1))
        sim.step(6)
        out.append((*sim.robot_state(), *sim.ekf_state()))
    return np.concatenate([np.concatenate(s) for s in out])


def _momentum(sim):
    """Linear momentum of every robot link and bag part/node (world frame)."""
    p, c = sim.p, sim.client
    tot = np.zeros(3)
    for r in sim.robots.values():
        tot += p.getDynamicsInfo(r.id, -1, physicsClientId=c)[0] * np.array(
            p.getBaseVelocity(r.id, physicsClientId=c)[0])
        for link in range(p.getNumJoints(r.id, physicsClientId=c)):
            tot += p.getDynamicsInfo(r.id, link, physicsClientId=c)[0] * np.array(
                p.getLinkState(r.id, link, computeLinkVelocity=1, physicsClientId=c)[6])
    b = sim.bag
    if b is not None:
        if hasattr(b, "parts"):
            for part in b.parts:
                tot += p.getDynamicsInfo(part, -1, physicsClientId=c)[0] * np.array(
                    p.getBaseVelocity(part, physicsClientId=c)[0])
        elif hasattr(b, "springs"):
            tot += b.springs.node_mass * b.v[:, 0, :].sum(axis=0)
        else:                              # Bullet soft body: centroid velocity (differenced)
            tot += b.mass * sim.bag_state().velocity
    return tot


# ---- the knobs ------------------------------------------------------------------------------
def test_presets_load_round_trip_and_off_is_off():
    assert set(presets()) >= {"off", "astrobee", "harsh"}
    assert not Realism.preset("off").enabled and Realism.preset("off") == Realism()
    for name in presets():
        r = Realism.preset(name)
        assert Realism.from_dict(r.to_dict()) == r
    a, h = Realism.preset("astrobee"), Realism.preset("harsh")
    assert 0.005 <= a.ekf_position_noise <= 0.03 and 0.005 <= a.ekf_attitude_noise <= 0.04
    assert 0.1 <= a.propulsion_lag <= 0.2 and a.actuation_noise == pytest.approx(0.05)
    assert h.ekf_position_noise > a.ekf_position_noise and h.propulsion_lag > a.propulsion_lag
    assert h.disturbances and h.disturbances[0].magnitude > 0
    r = resolve({"preset": "astrobee", "bag_mass_told": 0.0})
    assert r.bag_mass_told == 0.0 and r.propulsion_lag == a.propulsion_lag


@pytest.mark.parametrize("bad,needle", [
    ({"ekf_position_noise": -0.1}, "ekf_position_noise"),
    ({"propulsion_lag": "slow"}, "propulsion_lag"),
    ({"wind": 1}, "unknown realism knob 'wind'"),
    ({"bag_stiffness_scale": 0}, "bag_stiffness_scale"),
    ({"disturbances": [{"target": "wall", "magnitude": 1}]}, "target"),
    ({"disturbances": [{"force": [1, 2]}]}, "force"),
    ({"disturbances": [{"time": 1.0}]}, "force [x, y, z] or a magnitude"),
    ({"disturbances": [{"magnitude": 1, "duration": 0}]}, "duration"),
    ({"preset": "calm"}, "unknown realism preset 'calm'"),
    ("calm", "unknown realism preset"),
    (3, "preset name"),
])
def test_bad_values_are_one_line_errors(bad, needle):
    with pytest.raises(ScenarioError) as e:
        resolve(bad)
    assert needle in str(e.value) and "\n" not in str(e.value)


def test_scenario_realism_section_and_override():
    data = {"robots": [{"name": "", "position": [10.95, 0, 4.84]}],
            "realism": {"preset": "astrobee", "bag_mass_told": 0.5}}
    sc = Scenario.from_dict(data, "x")
    assert sc.realism.bag_mass_told == 0.5 and sc.realism.propulsion_lag > 0
    assert Scenario.from_dict(sc.as_dict(), "x").realism == sc.realism      # /sim/scenario YAML
    assert Scenario.from_dict({**data, "realism": "harsh"}, "x").realism == Realism.preset("harsh")
    assert not Scenario.load("node2_to_jem").realism.enabled
    assert "realism" not in Scenario.load("node2_to_jem").as_dict()         # off: YAML unchanged
    assert Scenario.load("node2_to_jem", realism="astrobee").realism == Realism.preset("astrobee")
    assert Scenario.load("node2_to_jem", realism=Realism(ekf_omega_noise=0.1)).realism.ekf_noisy
    with pytest.raises(ScenarioError, match="ekf_attitude_noise"):
        Scenario.from_dict({**data, "realism": {"ekf_attitude_noise": -1}}, "x")


# ---- EKF noise (the model alone: many samples, no physics) -----------------------------------
def test_ekf_noise_and_bias_statistics():
    r = Realism(ekf_position_noise=0.02, ekf_attitude_noise=0.01, ekf_velocity_noise=0.005,
                ekf_omega_noise=0.003, ekf_position_bias=0.03, ekf_attitude_bias=0.02)
    e = RealismEffects(r, 7, [""], 1 / 350, False)
    n = 4000
    samples = [e.ekf("", k, STATE) for k in range(n)]
    dp = np.array([s[0] - STATE[0] for s in samples])
    da = np.array([rot.to_rotvec(rot.multiply(rot.conjugate(STATE[1]), s[1])) for s in samples])
    dv = np.array([s[2] - STATE[2] for s in samples])
    dw = np.array([s[3] - STATE[3] for s in samples])
    tol = 4 / np.sqrt(2 * n)            # std of a sample std, ~4 sigma
    for d, sigma in ((dp, 0.02), (da, 0.01), (dv, 0.005), (dw, 0.003)):
        assert np.all(np.abs(d.std(axis=0) / sigma - 1) < tol), (d.std(axis=0), sigma)
    # one run's bias is constant: the sample means are it (noise std / sqrt(n) around it)
    bp, ba = e.bias[""]
    assert np.all(np.abs(dp.mean(axis=0) - bp) < 4 * 0.02 / np.sqrt(n))
    assert np.all(np.abs(da.mean(axis=0) - ba) < 4 * 0.01 / np.sqrt(n) + 1e-4)
    # across runs (seeds) the bias has the configured std
    biases = np.array([RealismEffects(r, s, [""], 1 / 350, False).bias[""][0] for s in range(600)])
    assert np.all(np.abs(biases.std(axis=0) / 0.03 - 1) < 4 / np.sqrt(2 * 600))
    assert np.all(np.abs(biases.mean(axis=0)) < 4 * 0.03 / np.sqrt(600))


def test_ekf_noise_depends_on_seed_and_step_not_on_the_call_pattern():
    r = Realism.preset("astrobee")
    a, b, c = (RealismEffects(r, s, ["", "bumble"], 1 / 350, False) for s in (1, 1, 2))
    for _ in range(3):
        a.ekf("", 5, STATE)                      # extra reads change nothing
    assert all(np.array_equal(x, y) for x, y in zip(a.ekf("", 10, STATE), b.ekf("", 10, STATE)))
    assert not np.array_equal(a.ekf("", 10, STATE)[0], c.ekf("", 10, STATE)[0])
    assert not np.array_equal(a.ekf("", 10, STATE)[0], a.ekf("", 11, STATE)[0])
    assert not np.array_equal(a.ekf("", 10, STATE)[0], a.ekf("bumble", 10, STATE)[0])


# ---- the simulator ----------------------------------------------------------------------------
def test_realism_off_is_the_truth_and_the_same_flight(make_sim):
    base = make_sim("node2_to_jem_bag", seed=4)
    off = make_sim("node2_to_jem_bag", seed=4, realism="off")
    told = make_sim("node2_to_jem_bag", seed=4, realism={"bag_mass_told": 0.0})   # not physics
    assert base.effects is None and off.effects is None and told.effects is None
    assert off.realism == Realism() and not base.realism.enabled
    fb, fo, ft = _fly(base), _fly(off), _fly(told)
    assert np.array_equal(fb, fo) and np.array_equal(fb, ft)
    for s in (base, off):
        assert all(np.array_equal(x, y) for x, y in zip(s.ekf_state(), s.robot_state()))
    assert base.told_bag_mass() == 10.0 and told.told_bag_mass() == 0.0
    assert base.disturbance_log == []


def test_same_seed_same_noise_other_seed_other_noise(make_sim):
    kw = {"realism": "astrobee", "bag_model": "none"}
    a, b, c = (make_sim("node2_to_jem_bag", seed=s, **kw) for s in (1, 1, 2))
    fa, fb, fc = _fly(a, 30), _fly(b, 30), _fly(c, 30)
    assert np.array_equal(fa, fb) and not np.array_equal(fa, fc)
    pos, q, v, w = a.robot_state()
    e = a.ekf_state()
    assert 1e-4 < np.linalg.norm(e[0] - pos) < 0.2 and a.told_bag_mass() == 0.0


def test_propulsion_lag_reaches_63_percent_after_one_time_constant(make_sim):
    tau = 0.2
    sim = make_sim("node2_to_jem", realism={"propulsion_lag": tau})
    cmd = np.array([0.3, -0.2, 0.1, 0.02, 0.01, -0.01])
    sim.command(cmd)
    k = int(round(tau / sim.dt))
    sim.step(k)
    assert sim.effects.applied[""] == pytest.approx(cmd * (1 - np.exp(-k * sim.dt / tau)), rel=1e-9)
    assert sim.effects.applied[""] / cmd == pytest.approx(np.full(6, 1 - np.exp(-1)), abs=0.01)
    for _ in range(2):                 # re-commanded within the propulsion watchdog's 0.32 s
        sim.command(cmd)
        sim.step(k)
    assert sim.effects.applied[""] / cmd == pytest.approx(np.full(6, 1 - np.exp(-3)), abs=0.01)


def test_actuation_noise_stays_within_the_flight_mode(make_sim):
    sim = make_sim("node2_to_jem", realism={"actuation_noise": 0.5})
    lim = np.concatenate([sim.flight_mode.max_force, sim.flight_mode.max_torque])
    seen = []
    for _ in range(40):
        sim.command(lim * 0.9)
        sim.step(6)
        seen.append(sim.effects.applied[""].copy())
    seen = np.array(seen)
    assert np.all(np.abs(seen) <= lim + 1e-12) and seen.std(axis=0).min() > 0


@pytest.mark.parametrize("model,solver,target", [
    (None, None, "robot"), ("rigid", None, "bag"), ("composite", None, "bag"),
    ("fem", "fast", "bag"), ("fem", "bullet", "bag")])
def test_disturbance_pulse_gives_its_impulse(make_sim, model, solver, target):
    """Bullet's soft body takes no external force: the pulse is a gravity field over it with
    the robots held by opposite forces; its momentum is read from differenced node positions
    (2%)."""
    force, duration = np.array([2.0, 1.0, -0.5]), 0.5
    r = {"disturbances": [{"time": 0.1, "target": target, "force": force.tolist(),
                           "duration": duration}]}
    kw = {"bag_model": model, "fem_solver": solver} if model else {}
    sim = make_sim("node2_to_jem_bag" if model else "node2_to_jem", realism=r, **kw)
    sim.step(10)
    p0 = _momentum(sim)
    assert sim.disturbance_log == []
    sim.step(300)
    dp = _momentum(sim) - p0
    tol = 0.02 if solver == "bullet" else 0.01
    assert dp == pytest.approx(force * duration, abs=tol * np.linalg.norm(force) * duration)
    (entry,) = sim.disturbance_log
    assert entry["applied"] and entry["target"] == target
    assert entry["time"] == pytest.approx(0.1) and entry["impulse"] == pytest.approx(force * duration)


def test_random_disturbance_is_drawn_from_the_seed(make_sim):
    r = {"disturbances": [{"magnitude": 3.0, "t_min": 0.05, "t_max": 0.15, "duration": 0.05}]}
    a, b, c = (make_sim("node2_to_jem", seed=s, realism=r) for s in (5, 5, 6))
    sa, sb, sc = a.disturbance_schedule(), b.disturbance_schedule(), c.disturbance_schedule()
    assert sa == sb and sa != sc
    assert 0.05 - a.dt <= sa[0]["time"] <= 0.15 + a.dt
    assert np.linalg.norm(sa[0]["force"]) == pytest.approx(3.0)
    a.step(70)
    assert len(a.disturbance_log) == 1
    none = make_sim("node2_to_jem", realism={"disturbances": [{"target": "bag", "magnitude": 1.0,
                                                               "time": 0.0}]})
    none.step(5)
    assert none.disturbance_log[0]["applied"] is False          # no bag: logged, not applied
    with pytest.raises(ScenarioError, match="no robot 'honey'"):
        make_sim("node2_to_jem", realism={"disturbances": [{"robot": "honey", "magnitude": 1}]})


def test_bag_stiffness_and_damping_scales_reach_the_bag_model(make_sim):
    soft = make_sim("node2_to_jem_bag", bag_model="fem", fem_solver="fast",
                    realism={"bag_stiffness_scale": 0.5, "bag_damping_scale": 2.0})
    assert soft.bag.springs.stiffness == pytest.approx(25.0)
    assert soft.bag.springs.damping == pytest.approx(0.2)
    c = make_sim("node2_to_jem_bag", bag_model="constraint", realism={"bag_stiffness_scale": 2.0})
    assert c.bag.params["max_force"] == pytest.approx(5.0)


def test_snapshot_restore_with_realism_on_continues_identically(make_sim):
    """Robot only: pybullet's restoreState of the rigid bag's grasp constraint is itself not
    bit-exact (1e-5 m, with or without realism); the realism state (lag, noise, log) is."""
    r = Realism.preset("astrobee").to_dict()
    r["disturbances"] = [{"time": 0.4, "target": "robot", "magnitude": 2.0, "duration": 0.2}]
    sim = make_sim("node2_to_jem", seed=9, realism=r)
    _fly(sim, 10)
    snap = sim.snapshot()
    first = _fly(sim, 30)
    log = sim.disturbance_log
    assert len(log) == 1
    sim.restore(snap)
    assert sim.disturbance_log == []
    assert np.array_equal(_fly(sim, 30), first) and sim.disturbance_log == log


# ---- the graph ------------------------------------------------------------------------------
@pytest.mark.graph
def test_sim_node_tells_the_controller_the_wrong_mass_and_publishes_the_realism():
    import yaml

    roszen = pytest.importorskip("roszen")
    from roszen import testing
    with testing.router() as port:
        env = testing.zenoh_env(port)
        args = ["-m", "astrobee_sim.sim_node", "--ros-args", "-p", "scenario:=node2_to_jem_bag",
                "-p", "realism:=astrobee", "-p", "realism.bag_mass_told:=0.5",
                "-p", "realism.disturbance_time:=0.0", "-p", "realism.disturbance_target:=robot",
                "-p", "realism.disturbance_force:=[0.5, 0.0, 0.0]",
                "-p", "realism.disturbance_duration:=0.1", "-p", "clock_mode:=fast"]
        sim = testing.spawn(testing.python_cmd(*args), env)
        ctx = roszen.Context(env=env)
        node = roszen.Node("realism_test", context=ctx)
        try:
            got = {}
            node.create_subscription("astrobee_msgs/msg/ScenarioInfo", "/sim/scenario",
                                     lambda m: got.__setitem__("info", m), roszen.LATCHED)
            node.create_subscription("std_msgs/msg/String", "/sim/realism",
                                     lambda m: got.__setitem__("realism", yaml.safe_load(m.data)),
                                     roszen.LATCHED)

            def ready():
                return "info" in got and got.get("realism", {}).get("applied")
            end = __import__("time").monotonic() + 40
            while not ready() and __import__("time").monotonic() < end and sim.poll() is None:
                node.spin_once(timeout_sec=0.05)
            assert ready(), sim.stderr.read()[-2000:] if sim.poll() is not None else got
            info = got["info"]
            assert info.bag_mass == pytest.approx(5.0) and info.bag_mass_true == pytest.approx(10.0)
            knobs = yaml.safe_load(info.realism)
            assert knobs["bag_mass_told"] == 0.5 and knobs["propulsion_lag"] == pytest.approx(0.15)
            (pulse,) = got["realism"]["applied"]
            assert pulse["target"] == "robot" and pulse["force"] == [0.5, 0.0, 0.0]
        finally:
            node.destroy_node()
            ctx.shutdown()
            testing.stop(sim)


@pytest.mark.graph
@pytest.mark.parametrize("params,needle", [
    (["realism:=calm"], "unknown realism preset 'calm'"),
    (["realism.ekf_position_noise:=-1"], "realism.ekf_position_noise"),
    (["realism.disturbance_target:=wall"], "realism.disturbance_target"),
    (["realism.disturbance_duration:=1.0"], "needs realism.disturbance_force"),
    (["backend:=rigid", "realism:=astrobee"], "backend rigid models no realism"),
])
def test_bad_realism_parameter_ends_sim_node_with_one_line(params, needle):
    from roszen import testing
    args = ["-m", "astrobee_sim.sim_node", "--ros-args"]
    for p in params:
        args += ["-p", p]
    r = subprocess.run(testing.python_cmd(*args), env=testing.zenoh_env(testing.free_port()),
                       capture_output=True, text=True, timeout=60)
    lines = [ln for ln in r.stderr.splitlines() if ln.startswith("sim_node: error:")]
    assert r.returncode == 1 and len(lines) == 1 and needle in lines[0], r.stderr
    assert "Traceback" not in r.stderr


def test_bad_realism_launch_argument_is_one_line_and_starts_nothing(tmp_path):
    r = subprocess.run([sys.executable, "-m", "astrobee_bringup.cli", "launch", "cargo_transport",
                        "realism:=calm"], capture_output=True, text=True, timeout=60,
                       cwd=tmp_path)
    assert r.returncode != 0 and "unknown realism preset 'calm'" in r.stderr, r.stderr
    assert "Traceback" not in r.stderr and not (tmp_path / "runs").exists()


def test_controller_takes_a_told_mass_of_zero_as_no_bag_mass():
    """controller_node's CarriedBag reads /sim/scenario's bag_mass: 0 (bag_mass_told 0) is
    accepted and the law then carries no bag mass (law.carried_mass)."""
    from types import SimpleNamespace

    from astrobee_control.controller_node import CarriedBag
    size = SimpleNamespace(x=0.5, y=0.42, z=0.25)
    bag = CarriedBag(0.0, [])
    bag.on_scenario(SimpleNamespace(carrying_bag=True, bag_mass=0.0, bag_size=size))
    mass, _ = bag.figures()
    assert mass == 0.0
    bag.on_scenario(SimpleNamespace(carrying_bag=True, bag_mass=5.0, bag_size=size))
    assert bag.figures()[0] == 5.0
    with pytest.raises(ValueError):
        bag.on_scenario(SimpleNamespace(carrying_bag=True, bag_mass=-1.0, bag_size=size))
