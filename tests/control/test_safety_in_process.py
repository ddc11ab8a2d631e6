"""The CBF safety filter in the controller's process (controller_node safety:=true) and in its own
(safety_filter_node) give the same command for the same input, and so does Flight's: all three
filter through safety.LawFilter. Nodes are built in this process and their callbacks
called directly (no spinning; the session router only lets the nodes be created)."""
from __future__ import annotations

import numpy as np
import pytest

from astrobee import flight_modes
from astrobee import msgconv as mc
from astrobee import rotations as rot
from astrobee_control import mass as mp
from astrobee_control.hold import HoldLaw
from astrobee_control.law import BagObservation
from astrobee_control.pd import State
from astrobee_control.safety import LawFilter, SafetyFilter, box_corners, carried_load

# node2_to_jem's start faces -y (body y = world +x); the end of the forward corridor (the
# nearest wall) is ~1.1 m along world +x: the test's robot flies at it, pushed on body +y
START = np.array([10.95, 0.0, 4.84])
Q = rot.from_axis_angle(np.array([0.0, 0.0, 1.0]), -np.pi / 2)
BAG_SIZE = np.array([0.25, 0.42, 0.50])
BAG_MASS = 4.0
BAG_OFFSET_BODY = np.array([0.45, 0.0, -0.05])


class PushLaw(HoldLaw):
    """A broken law: the hold law's command with full thrust on body +y (toward the wall)."""

    def update(self, state, now, dt):
        step = super().update(state, now, dt)
        step.output.force = np.array([0.0, self.flight_mode.max_force[1], 0.0])
        step.output.torque = np.array([0.0, 0.0, 0.02])
        return step


def ticks():
    """(time, State) samples flying at the wall faster and faster, then turning."""
    out = []
    for i in range(60):
        t = 1.0 + i / 62.5
        v = np.array([0.02 * i, 0.0, 0.0])
        p = START + np.array([0.012 * i * (1 + i / 60.0), 0.0, 0.0])
        w = np.array([0.0, 0.0, 0.01 * (i % 7)])
        out.append((t, State(p, v, Q.copy(), w)))
    return out


def bag_observation(state: State) -> BagObservation:
    pos = state.position + rot.rotate(state.orientation, BAG_OFFSET_BODY)
    return BagObservation(pos, state.orientation.copy(), state.velocity.copy(), np.zeros(3), True,
                          BAG_MASS, BAG_SIZE.copy(), "rigid")


@pytest.mark.graph
def test_controller_and_filter_node_give_the_same_command(router_env):
    import roszen
    from astrobee_control.controller_node import ControllerNode
    from astrobee_control.safety_filter_node import SafetyFilterNode

    def make_law(mode, mass, params):
        return PushLaw(mode, mass)

    M = roszen.message_class
    plain = ControllerNode(make_law, "plain_controller", argv=["--ros-args", "-r", "__ns:=/a"])
    safe = ControllerNode(make_law, "safe_controller",
                          argv=["--ros-args", "-r", "__ns:=/b", "-p", "safety:=true"])
    node = SafetyFilterNode(argv=["--ros-args", "-r", "__ns:=/c"])
    try:
        assert plain.safety is None and safe.safety is not None
        nominal, filtered, separate = [], [], []
        diag_in, diag_sep = [], []
        plain.pub_cmd.publish = nominal.append
        safe.pub_cmd.publish = filtered.append
        node.pub_cmd.publish = separate.append
        safe.safety_diagnostics.pub.publish = diag_in.append
        node.diagnostics.pub.publish = diag_sep.append

        scen = M("astrobee_msgs/msg/ScenarioInfo")()
        scen.name, scen.carrying_bag, scen.bag_mass, scen.bag_model = "t", True, BAG_MASS, "rigid"
        mc.set_vec(scen.bag_size, BAG_SIZE)
        mode = M("astrobee_msgs/msg/FlightMode")()
        mode.name = "nominal"
        for n in (plain, safe, node):
            n._on_scenario(scen)
            n._on_flight_mode(mode)
        active = 0
        for t, st in ticks():
            ekf = M("astrobee_msgs/msg/EkfState")()
            mc.set_stamp(ekf.header.stamp, t)
            mc.set_pose(ekf.pose, st.position, st.orientation)
            mc.set_vec(ekf.velocity, st.velocity)
            mc.set_vec(ekf.omega, st.omega)
            for n in (plain, safe, node):
                n._on_ekf(ekf)
            node._on_command(nominal[-1])          # the plain controller's command, filtered
            a, b = filtered[-1], separate[-1]
            assert mc.stamp_s(a.header.stamp) == mc.stamp_s(b.header.stamp) == pytest.approx(t)
            for part in ("force", "torque"):
                va = mc.vec(getattr(a.wrench, part))
                vb = mc.vec(getattr(b.wrench, part))
                assert np.array_equal(va, vb), (t, part, va, vb)
            active += not np.allclose(mc.vec(a.wrench.force), mc.vec(nominal[-1].wrench.force))
            # this tick's bag state reaches every node after its command (as on the graph)
            bag = M("astrobee_msgs/msg/BagState")()
            obs = bag_observation(st)
            mc.set_pose(bag.pose, obs.position, obs.orientation)
            bag.attached = [True, False]
            bag.model = "rigid"
            for n in (plain, safe, node):
                n._on_bag(bag)
        assert safe.safety.carrying and node.lf.carrying
        assert active > 5, "the wall never made the filter act: the test proves nothing"
        assert node.lf.ticks == safe.safety.ticks == len(ticks())
        assert node.lf.active_ticks == safe.safety.active_ticks > 5
        # the same latched diagnostics (type, fields, pace), the namespace aside
        assert len(diag_in) == len(diag_sep) >= 2
        for x, y in zip(diag_in, diag_sep):
            sx, sy = x.status[0], y.status[0]
            assert (sx.level, sx.name, sx.message) == (sy.level, sy.name, sy.message)
            assert [(kv.key, kv.value) for kv in sx.values] == [(kv.key, kv.value) for kv in sy.values]
        assert any(d.status[0].level == 1 for d in diag_in)
    finally:
        for n in (plain, safe, node):
            n.node.destroy_node()


def test_law_filter_is_the_filter_with_the_carried_bag():
    """LawFilter = SafetyFilter with the held bag's mass and corners (what safety_filter_node and
    Flight did by hand), rebuilt only on a 1 cm move; released back to the robot alone."""
    mode = flight_modes.get("nominal")
    lf = LawFilter(mode, mp.robot())
    raw = SafetyFilter(mode, mp.robot(), margin=0.05)
    f_nom = np.array([0.0, mode.max_force[1], 0.0])
    events = []
    for i, (t, st) in enumerate(ticks()):
        res = lf.apply(f_nom, np.zeros(3), st)
        if i < 20:
            ref = raw.filter(f_nom, np.zeros(3), st)
        else:
            offset, r_rel = bag_observation(st).offset_in(st)
            mprops, com = carried_load(mp.robot(), BAG_MASS, BAG_SIZE, offset, r_rel)
            raw.set_mass(mprops, com)
            ref = raw.filter(f_nom, np.zeros(3), st, extent=box_corners(offset, BAG_SIZE, r_rel))
        assert np.allclose(res.force, ref.force, atol=1e-9) and res.active == ref.active, (t, i)
        if i >= 19:
            events.append(lf.observe_bag(bag_observation(st), st))
    assert events[0] == "attached" and set(events[1:]) == {""}
    assert len(lf.extent) == 8 and lf.carrying
    assert lf.observe_bag(None, st) == "released" and lf.extent == [] and not lf.carrying
    assert lf.release() == ""
    assert lf.ticks == len(ticks()) and lf.active_ticks > 5


def test_law_filter_diagnostics_pace_and_content():
    """Published on a change of state, else at most diagnostics_rate Hz; the values the node
    has always published (recordings, plots and the Foxglove layout read them)."""
    mode = flight_modes.get("nominal")
    lf = LawFilter(mode, mp.robot(), diagnostics_rate=2.0)
    st = State(START.copy(), np.zeros(3), Q.copy(), np.zeros(3))
    res = lf.apply(np.zeros(3), np.zeros(3), st)
    assert lf.diagnostics_due(res, 0.0) and "transparent" in lf.transition(res)
    assert not lf.diagnostics_due(res, 0.2)
    assert lf.diagnostics_due(res, 0.6) and lf.transition(res) == ""
    # a simulation reset sends the clock back: the pace starts anew (not silent until t > 0.6)
    assert lf.diagnostics_due(res, 0.0) and not lf.diagnostics_due(res, 0.3)
    level, message, pairs = lf.status(res)
    assert (level, message) == (0, "transparent")
    assert [k for k, _ in pairs] == ["active", "delta_norm", "slack", "min_barrier", "omega_barrier",
                                     "fallback", "reason", "ticks", "active_ticks", "fallback_ticks"]
    with pytest.raises(ValueError):
        LawFilter(mode, margin=0.7)
    lf.set_flight_mode(flight_modes.get("quiet"))
    assert lf.filter.flight_mode.name == "quiet"
