"""The oracle: offline optimal control of the reduced pair model with the disturbance known in
advance (solve.py), its CasADi model (model.py), the LQR that tracks its plan (tracking.py), its
plan flown in the FEM simulator (fly.py) and the study's answers read back (feasibility.py:
load_feasibility). CasADi is imported only inside these modules' functions."""
from .feasibility import load_feasibility

__all__ = ["load_feasibility"]
