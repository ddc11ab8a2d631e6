"""The mission client: plan a scenario's route, hand it to the controller(s), follow it to the
end and write the run's summary.json (atomically) and plot.

One robot: a global plan (/mob/planner/global). Two robots (a scenario whose /sim/scenario lists
two, holding the cargo bag's two handles): a formation plan (/mob/planner/formation), one
segment per robot on `<ns>/gnc/ctl/segment`, all with the same start stamp. The leg ends when
astrobee.task says so: every robot within tolerance of its goal and at rest (truth) for 2 s, or
the time budget (plan end + --settle-budget, 30 s by default) out; or on a fault of any robot
(named in the reason). The Task judges the leg's samples (astrobee.leg_samples, the builder
recorded bags use too); per-robot figures and verdicts go into summary.json's legs[i].robots.

    python -m astrobee_bringup.mission --scenario node2_to_jem --run-dir runs/X [--scenario node2_to_jem_bag]

With several scenarios (the demo) the legs fly one after the other in the same graph, the
simulation reset to each leg's scenario (/sim/reset) before it. Exit status: 0 when every leg
succeeded, 1 when one failed, 2 for a bad argument, 130 when interrupted (SIGINT/SIGTERM).
The launch description runs it as one of its processes (see astrobee_bringup/launch/cargo_transport.py).

Deterministic lockstep (`--handover`, with sim_node's start_paused: the launch sets both in
lockstep): every leg starts from a paused sim. The mission waits until the graph is ready (each
robot's controller up, a recorder (`--await-recorder`) subscribed to every topic of the sim),
resets the sim (the state of t=0 published once, to every node), plans from that state, hands
the segments over stamped to start at t=0 + HANDOVER_LEAD and resumes the sim once every
controller holds its segment; the sim then runs in chunks (/sim/control RESUME with steps) and
the leg ends at the first chunk end after the Task ended it. Nothing depends on the wall
clock: the same seed gives the same recording (tests/e2e/test_determinism_launch.py).

Lost peers: the simulator, the planner or a flying robot's controller leaving the graph (even
kill -9) fails the leg at once with "lost node <name>" (roszen.peers.PeerWatch).

Modules: cli (arguments, the run), client (the node, waiting, peers), resets (the sim brought
to a scenario), watch (one robot followed), planning (the plan's segments), leg (one leg,
phase by phase), result (LegResult, the Task's judgement, summary.json), progress.
"""
from .cli import client_last, main, run_mission
from .client import MissionClient
from .leg import fly_leg
from .progress import Progress
from .result import Interrupted, LegResult, MissionError, finish_leg, write_outputs, write_summary
from .watch import RobotWatch

__all__ = ["Interrupted", "LegResult", "MissionClient", "MissionError", "Progress", "RobotWatch",
           "client_last", "finish_leg", "fly_leg", "main", "run_mission", "write_outputs",
           "write_summary"]
