"""What every Astrobee package shares: config loading, rotations, flight modes, the launcher,
the mission client and the `astrobee` command."""
