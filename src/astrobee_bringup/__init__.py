"""The application on top of the node packages: the `astrobee` command, the launcher and its
launch descriptions, the mission client and the run summary (imports every layer below)."""
