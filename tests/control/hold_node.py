"""A controller node running HoldLaw: proves a second law needs no node code of its own."""
import sys

from astrobee_control import controller_node
from astrobee_control.hold import HoldLaw

if __name__ == "__main__":
    sys.exit(controller_node.main(lambda mode, mass, params: HoldLaw(mode, mass),
                                  "hold_controller_node"))
