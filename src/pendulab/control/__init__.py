"""The student's controller: entry (Python, text, files, prompt), checks, and its discrete realization.

Examples
--------
>>> from pendulab.control import Controller, discretize, demo_controller
>>> lti = discretize(demo_controller(), h=1e-3)
>>> lti.to_parameters()["n"]
3
"""

from pendulab.control.controller import (
    MAX_FACTORS,
    Controller,
    Factor,
    demo_controller,
    format_numbers,
    parse_compensator,
    parse_controller,
    parse_numbers,
    unstable_example,
)
from pendulab.control.files import load_controller_file, save_controller_file
from pendulab.control.realization import MAX_ORDER, DiscreteLTI, discretize

__all__ = [
    "MAX_FACTORS",
    "MAX_ORDER",
    "Controller",
    "DiscreteLTI",
    "Factor",
    "demo_controller",
    "discretize",
    "format_numbers",
    "load_controller_file",
    "parse_compensator",
    "parse_controller",
    "parse_numbers",
    "save_controller_file",
    "unstable_example",
]
