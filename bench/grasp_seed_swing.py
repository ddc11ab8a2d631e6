"""The hinge grasp side by side with the seed's FEM bag (docs/grasp.md): swing amplitude and period.

The seed's bag: its own tet mesh (pyastrobee's assets/meshes/bags/front_handle.vtk, given by
path: it is not in this repository) with its material (mass 10 kg, elastic 50, damping 0.1,
bending 50, friction 0.1, damping in all directions) in pybullet, held as it holds it: two
soft-body anchors at the nodes nearest +-5 cm along the strap. Ours: the same size and mass,
grasp=hinge, fast and Bullet solvers. Both on the project's robot, walls removed.

Experiment: a constant 1 N force on the robot at 30 deg from its arm line (the bag trails along
-x body), attitude held by a stiff PD: the bag is a pendulum in the pseudo-gravity F/(M+m) and
swings +-30 deg about the trailing direction. Printed: first swing, peaks/troughs, period,
how often the bag touched the robot's body (sampled every 7 steps), beside a rigid-pendulum
estimate.

Why the seed's bag swings less: near 44 deg of swing its bag strikes the robot's aft-bottom
corner (Bullet's soft-rigid contact with the robot's base, which the seed leaves on); `seed_free`
is the same bag with that one contact pair off (docs/grasp.md).

    .venv/bin/python bench/grasp_seed_swing.py /path/to/front_handle.vtk \
        [seed seed_free fast bullet] [--seconds 36]
"""
import argparse
import time

import numpy as np

from astrobee import rotations as rot

F, ALPHA, T_END = 1.0, np.radians(30.0), 36.0
VTK = ""                    # the seed's front_handle.vtk (command line)
KQ, KW = 3.0, 2.0


def drive(p, c, robot, step_fn, centroid_fn, q0, x_b, z_b, dt, touch_fn):
    """Push and hold attitude; (time, swing angle) every 7 steps, the CPU seconds and how many
    of those samples found the bag touching the robot's body (touch_fn)."""
    f = F * (np.cos(ALPHA) * x_b + np.sin(ALPHA) * z_b)
    out, touched = [], 0
    n = int(T_END / dt)
    c0 = time.process_time()
    for i in range(n):
        pos, q, v, w = robot.state()
        err = rot.to_rotvec(rot.multiply(q, rot.conjugate(q0)))
        tau = -KQ * err - KW * np.asarray(w)
        com = robot.com()
        p.applyExternalForce(robot.id, -1, f.tolist(), com.tolist(), p.WORLD_FRAME, physicsClientId=c)
        p.applyExternalTorque(robot.id, -1, tau.tolist(), p.WORLD_FRAME, physicsClientId=c)
        step_fn()
        if i % 7 == 0:
            tip, _ = robot.gripper_tip()
            d = centroid_fn() - tip
            out.append((i * dt, np.arctan2(-(d @ z_b), -(d @ x_b))))
            touched += bool(touch_fn())
    return np.array(out), time.process_time() - c0, touched


def analyse(tr):
    """First swing, peaks and troughs (deg) and the period (s) of an angle trace."""
    t, th = tr[:, 0], np.degrees(tr[:, 1])
    # peaks (local maxima) of theta
    pk = [i for i in range(1, len(th) - 1) if th[i] >= th[i - 1] and th[i] > th[i + 1] and th[i] > 30]
    tr_ = [i for i in range(1, len(th) - 1) if th[i] <= th[i - 1] and th[i] < th[i + 1] and th[i] < 30]
    period = np.diff(t[pk]).mean() if len(pk) > 1 else (2 * abs(t[tr_[1]] - t[pk[0]]) if len(tr_) > 1 and pk else float("nan"))
    first_amp = (th[pk[0]] - th[0]) / 2 if pk else float("nan")
    return {"peak1_deg": th[pk[0]] if pk else float("nan"), "amp1_deg": first_amp,
            "period_s": period, "t_peaks": [round(float(t[i]), 2) for i in pk],
            "peaks": [round(float(th[i]), 1) for i in pk], "troughs": [round(float(th[i]), 1) for i in tr_]}


def seed_bag(robot_contact: bool = True):
    """The seed's bag on our robot: (angle trace, CPU s, touching samples, nodes).
    robot_contact False: its contact with the robot's base (body) turned off."""
    import pybullet as p
    from astrobee_sim.robot import Robot
    from astrobee_sim.bags.base import align
    c = p.connect(p.DIRECT)
    p.resetSimulation(p.RESET_USE_DEFORMABLE_WORLD, physicsClientId=c)
    p.setGravity(0, 0, 0, physicsClientId=c)
    dt = 1 / 350.0
    p.setTimeStep(dt, physicsClientId=c)
    q_r = np.array([0.0, 0.0, -0.7071067811865476, 0.7071067811865476])
    robot = Robot(c, "", np.array([10.95, 0.0, 4.84]), list(q_r), "nominal", False)
    robot.deploy_arm(True, instant=True)
    robot.gripper(False, instant=True)
    tip, g = robot.gripper_tip()
    _, qr = robot.pose()
    g_body = rot.rotate_inverse(qr, g)
    q = rot.multiply(qr, align(np.array([0, -1.0, 0]), -g_body))
    hp = np.array([0, -0.16, 0])
    centre = tip - rot.rotate(q, hp)
    bag = p.loadSoftBody(VTK, basePosition=centre.tolist(),
                         baseOrientation=q.tolist(), scale=1.0, mass=10.0, useMassSpring=1,
                         useBendingSprings=1, useNeoHookean=0, springElasticStiffness=50.0,
                         springDampingStiffness=0.1, springBendingStiffness=50.0,
                         springDampingAllDirections=1, useSelfCollision=0, frictionCoeff=0.1,
                         useFaceContact=1, physicsClientId=c)
    p.setPhysicsEngineParameter(sparseSdfVoxelSize=0.25, physicsClientId=c)
    for ln in ("gripper", "arm_distal", "arm_proximal"):
        p.setCollisionFilterPair(bag, robot.id, -1, robot.links[ln], 0, physicsClientId=c)
    if not robot_contact:
        p.setCollisionFilterPair(bag, robot.id, -1, -1, 0, physicsClientId=c)

    def nodes():
        return np.asarray(p.getMeshData(bag, -1, flags=p.MESH_DATA_SIMULATION_MESH, physicsClientId=c)[1])
    x = nodes()
    pins = []
    for s in (1, -1):
        target = centre + rot.rotate(q, hp + s * np.array([0.05, 0, 0]))
        i = int(np.argmin(np.linalg.norm(x - target, axis=1)))
        p.createSoftBodyAnchor(bag, i, robot.id, robot.links["gripper"], physicsClientId=c)
        pins.append(x[i])
    print("seed's mesh as a rigid pendulum: period %.2f s, pivot-centroid %.3f m, I_c %.3f kg m^2"
          % mesh_estimate(x, 0.5 * (pins[0] + pins[1]), pins[0] - pins[1]))
    x_b = rot.rotate(qr, [1.0, 0, 0])
    z_b = rot.rotate(qr, [0, 0, 1.0])

    def step():
        robot.apply()
        p.stepSimulation(physicsClientId=c)
    tr, cpu, touched = drive(p, c, robot, step, lambda: nodes().mean(axis=0), qr, x_b, z_b, dt,
                             lambda: p.getContactPoints(bag, robot.id, physicsClientId=c))
    return tr, cpu, touched, len(x)


def our_bag(solver, res):
    """Our FEM bag (hinge) at the seed's size: (angle trace, CPU s, touching samples, nodes)."""
    from dataclasses import replace
    from astrobee.scenario import Scenario
    from astrobee_sim.simulation import Simulation
    sc = Scenario.load("node2_to_jem_bag", bag_model="fem", bag_resolution=res, fem_solver=solver,
                       grasp="hinge")
    sc = replace(sc, bag=replace(sc.bag, size=(0.50, 0.25, 0.42), mass=10.0))
    sim = Simulation(sc)
    p, c = sim.p, sim.client
    for w in sim.wall_ids:                       # open space, as the seed's run
        p.removeBody(w, physicsClientId=c)
    if solver == "fast":
        sim.bag.walls = np.zeros((0, 6))
        sim.bag._walls_grown = np.zeros((0, 6))
    robot = sim.robots[""]
    b = sim.bag
    print("our mesh as a rigid pendulum: period %.2f s, pivot-centroid %.3f m, I_c %.3f kg m^2"
          % mesh_estimate(b.mesh.nodes, b.handle_point(0), b.strap_axis(0)))
    _, qr, _, _ = robot.state()
    x_b = rot.rotate(qr, [1.0, 0, 0])
    z_b = rot.rotate(qr, [0, 0, 1.0])

    def step():
        sim.command(np.zeros(6), "")
        sim.step(1)
    if solver == "fast":      # the bag's contact push on the robot's body box, pending
        def touch():
            return any(e[5] is not None for e in sim.bag._pending)
    else:
        def touch():
            return p.getContactPoints(sim.bag.id, robot.id, physicsClientId=c)
    tr, cpu, touched = drive(p, c, robot, step, lambda: sim.bag.points().mean(axis=0), qr, x_b,
                             z_b, sim.dt, touch)
    n = len(sim.bag.points())
    sim.close()
    return tr, cpu, touched, n


def mesh_estimate(x, pivot, axis, m=10.0, M=9.583788668):
    """The same rigid pendulum with a mesh's own mass layout (equal node masses, as both FEM
    bags spread their mass): (period s, pivot-centroid distance m, I_c about the axis kg m^2)."""
    axis = np.asarray(axis, float) / np.linalg.norm(axis)
    r = np.asarray(x, float) - pivot
    r = r - np.outer(r @ axis, axis)
    d = float(np.linalg.norm(r.mean(axis=0)))
    i_c = m / len(r) * float((r ** 2).sum()) - m * d * d
    g, mu = F / (M + m), m * M / (m + M)
    return 2 * np.pi / np.sqrt(m * g * d / (i_c + mu * d * d)), d, i_c


def estimate(m=10.0, M=9.583788668, d=0.125 + 0.035, W=0.25, H=0.42):
    """Rigid pendulum on a free carrier: omega^2 = m g d / (I_c + mu d^2), g = F/(M+m)."""
    g = F / (M + m)
    I_c = m * (W * W + H * H) / 12
    mu = m * M / (m + M)
    w2 = m * g * d / (I_c + mu * d * d)
    return 2 * np.pi / np.sqrt(w2)


if __name__ == "__main__":
    ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
    ap.add_argument("vtk", help="the seed's front_handle.vtk")
    ap.add_argument("which", nargs="*", default=["seed", "seed_free", "fast", "bullet"],
                    choices=["seed", "seed_free", "fast", "bullet"])
    ap.add_argument("--seconds", type=float, default=T_END)
    a = ap.parse_args()
    VTK, T_END, which = a.vtk, a.seconds, a.which
    print(f"pendulum estimate (rigid 10 kg box 0.50x0.25x0.42, pivot 0.16 m off its centre, robot "
          f"9.58 kg, {F} N): period {estimate():.2f} s; with our 0.165 m pivot "
          f"{estimate(d=0.165):.2f} s; amplitude {np.degrees(ALPHA):.0f} deg")
    for w in which:
        if w.startswith("seed"):
            tr, cpu, touched, n = seed_bag(robot_contact=(w == "seed"))
        else:
            tr, cpu, touched, n = our_bag(w, 480)
        print(w, n, "nodes", f"cpu {cpu:.1f}s", f"touching the robot in {touched} of {len(tr)} "
              f"samples", analyse(tr), flush=True)
