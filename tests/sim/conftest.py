import pytest

from astrobee_sim.simulation import Simulation


@pytest.fixture
def make_sim():
    sims = []

    def make(*a, **kw):
        s = Simulation(*a, **kw)
        sims.append(s)
        return s
    yield make
    for s in sims:
        s.close()
