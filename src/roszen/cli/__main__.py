import sys

from roszen.cli import main

sys.exit(main(prog="roszen"))
