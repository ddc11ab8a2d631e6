"""The oracle: offline optimal control of the reduced pair model with the disturbance known in
advance (solve.py), its CasADi model (model.py) and its plan flown in the FEM simulator (fly.py).
CasADi is imported only inside these modules' functions."""
