"""Monte Carlo studies of cargo-transport flights: a study file (spec) expanded into flights,
flown in-process, on a pool or on Ray (run), reported as markdown and one HTML page (report,
html, stats: Wilson intervals, McNemar, Wilcoxon), a row re-flown through the graph (reflow),
and the `astrobee study` verb (cli)."""
from .run import StudyRun, StudyStore, read_table, run_study
from .spec import FlightSpec, Study, StudyError, load_study, parse_study

__all__ = ["FlightSpec", "Study", "StudyError", "StudyRun", "StudyStore", "load_study",
           "parse_study", "read_table", "run_study"]
