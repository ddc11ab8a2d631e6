"""Test launch description: a router plus small Python processes with chosen behaviours.

Launch argument `nodes`: comma-separated behaviours, each one of
  sleep     prints 'ready' and runs until signalled
  crash     prints 'ready', exits with code 3 after 0.5 s (required)
  noint     ignores SIGINT (stops on SIGTERM)
  noterm    ignores SIGINT and SIGTERM (needs SIGKILL)
  optional_crash   like crash but not required
"""
import sys

from astrobee_bringup.process_group import NodeSpec

CODE = {
    "sleep": "import time\nprint('ready', flush=True)\nwhile True: time.sleep(0.05)",
    "crash": "import time, sys\nprint('ready', flush=True)\ntime.sleep(0.5)\n"
             "print('crashing now', flush=True)\nsys.exit(3)",
    "noint": "import signal, time\nsignal.signal(signal.SIGINT, signal.SIG_IGN)\n"
             "print('ready', flush=True)\nwhile True: time.sleep(0.05)",
    "noterm": "import signal, time\nsignal.signal(signal.SIGINT, signal.SIG_IGN)\n"
              "signal.signal(signal.SIGTERM, signal.SIG_IGN)\nprint('ready', flush=True)\n"
              "while True: time.sleep(0.05)",
}
CODE["optional_crash"] = CODE["crash"]


def generate_nodes(ctx):
    specs = [NodeSpec("router", kind="router", command=["router", "--port", str(ctx.port)])]
    for i, kind in enumerate(ctx.arg("nodes", "sleep").split(",")):
        specs.append(NodeSpec(f"{kind}{i}", argv=[sys.executable, "-c", CODE[kind]],
                              required=kind != "optional_crash"))
    return specs
