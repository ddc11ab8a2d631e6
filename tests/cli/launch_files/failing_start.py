"""Test launch description: a router, a real roszen node (the adder), a stand-in mission that
writes an "interrupted" summary.json when stopped, and a node that cannot start (prints one
error line, exits 1) once `bad:=true`."""
import sys

from astrobee_bringup.process_group import NodeSpec

ARGUMENTS = {
    "bad": ("true", "true: the node 'broken' fails at start"),
}
HERE = __file__.rsplit("/", 2)[0]

MISSION = """
import json, signal, sys, time
def stop(*_):
    json.dump({"success": False, "status": "interrupted",
               "legs": [{"scenario": "x", "reason": "interrupted (SIGINT/SIGTERM)"}],
               "reason": "interrupted (SIGINT/SIGTERM)"}, open(sys.argv[1], "w"))
    sys.exit(130)
signal.signal(signal.SIGINT, stop)
print("mission up", flush=True)
while True:
    time.sleep(0.05)
"""
BROKEN = """
import sys, time
time.sleep(1.0)
print("broken: loading things", flush=True)
print("broken: error: parameter rate must be > 0, got -1", file=sys.stderr, flush=True)
sys.exit(1)
"""


def generate_nodes(ctx):
    ctx.run_dir.mkdir(parents=True, exist_ok=True)
    specs = [NodeSpec("router", kind="router", command=["router", "--port", str(ctx.port)]),
             NodeSpec("adder", argv=[sys.executable, f"{HERE}/adder_node.py"]),
             NodeSpec("mission", kind="client",
                      argv=[sys.executable, "-c", MISSION, str(ctx.run_dir / "summary.json")])]
    if ctx.flag("bad", True):
        specs.append(NodeSpec("broken", argv=[sys.executable, "-c", BROKEN]))
    return specs
