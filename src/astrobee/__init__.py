"""What every Astrobee package shares: config loading, rotations, flight modes, the launcher,
the mission client and the `astrobee` command."""

from pathlib import Path as _Path

# Our interface package (astrobee_msgs) lives at the project root; an editable install or a
# source checkout finds it there. ROSZEN_INTERFACE_PATH can point elsewhere.
_MSGS = _Path(__file__).resolve().parents[2] / "astrobee_msgs"
if _MSGS.is_dir():
    try:
        import roszen.typestore as _typestore

        _typestore.register_interface_path(_MSGS)
    except ImportError:  # roszen not importable: the typestore is not needed then
        pass
