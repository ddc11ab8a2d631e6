"""pybullet's "build time" banner is dropped from a normal run's output; anything else written to
stderr while pybullet loads still comes out, and an import error still raises."""
import subprocess
import sys


def _run(code, tmp_path=None):
    env_path = [str(tmp_path)] if tmp_path else []
    return subprocess.run([sys.executable, "-c", f"import sys; sys.path[:0] = {env_path!r}\n{code}"],
                          capture_output=True, text=True, timeout=120)


def test_a_simulation_prints_no_banner():
    r = _run("from astrobee_sim.simulation import Simulation\n"
             "with Simulation('node2_to_jem_bag', bag_model='fem') as s:\n    s.step(2)\n"
             "print('done')")
    assert r.returncode == 0, r.stderr
    assert r.stdout == "done\n" and "build time" not in r.stderr, (r.stdout, r.stderr)


def test_other_output_while_loading_is_kept(tmp_path):
    """A stand-in pybullet writing the banner and a real message to file descriptor 2."""
    (tmp_path / "pybullet.py").write_text(
        "import os\nos.write(2, b'pybullet build time: Jan 1 2025\\nreal trouble\\n')\nX = 1\n")
    r = _run("from astrobee_sim.pybullet_import import pybullet\nprint(pybullet().X)", tmp_path)
    assert r.returncode == 0 and r.stdout == "1\n", r.stderr
    assert r.stderr == "real trouble\n"


def test_an_import_error_still_raises(tmp_path):
    (tmp_path / "pybullet.py").write_text("import os\nos.write(2, b'broken build\\n')\n"
                                          "raise ImportError('no bullet here')\n")
    r = _run("from astrobee_sim.pybullet_import import pybullet\npybullet()", tmp_path)
    assert r.returncode != 0
    assert "broken build" in r.stderr and "ImportError: no bullet here" in r.stderr


def test_quiet_drops_only_the_named_lines_on_both_descriptors():
    r = _run("import os\nfrom astrobee_sim.pybullet_import import SOFT_BODY, quiet\n"
             "with quiet(SOFT_BODY):\n"
             "    os.write(1, b'Nodes:  196\\nkept out\\nTetras: 636\\n')\n"
             "    os.write(2, b'Faces:  292\\nkept err\\n')\n"
             "print('after')")
    assert r.returncode == 0, r.stderr
    assert r.stdout == "kept out\nafter\n" and r.stderr == "kept err\n", (r.stdout, r.stderr)
