"""The `bsfjax` command line: `demo`, `example`, `transfer`, `reproduce`, `spectrum`.

Bad input ends with one line on stderr and exit status 2, never a traceback, and no partial
output file: every output of a command is written atomically, after all the work is done.
"""

from ._demo import example_landmarks, format_table, run_demo
from ._io import CLIError, TURN_DOUBT
from ._main import main
from ._parser import build_parser

__all__ = [
    "CLIError", "TURN_DOUBT", "build_parser", "example_landmarks", "format_table", "main",
    "run_demo",
]
