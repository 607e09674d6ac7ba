"""Command-line options shared by several subcommands."""

from __future__ import annotations

import argparse

from pendulab.model.parameters import CARTS, PENDULUMS, PlantParameters


def add_plant_options(parser: argparse.ArgumentParser, *, pendulums: tuple[str, ...] = ("long", "short")) -> None:
    """``--pendulum``, ``--cart`` and ``--calibration``."""
    parser.add_argument("--pendulum", default="long", metavar="|".join(pendulums), help="pendulum (default long)")
    parser.add_argument("--cart", default="ip02", metavar="|".join(CARTS), help="cart (default ip02, no load)")
    parser.add_argument("--calibration", metavar="FILE", help="calibration file (JSON, or the old lab's .mat)")


def plant_parameters_from_args(args: argparse.Namespace) -> PlantParameters:
    """Parameters of the preset named by the options, with the calibration file applied."""
    params = PlantParameters.preset(pendulum=args.pendulum, cart=args.cart)
    if getattr(args, "calibration", None):
        from pendulab.calibration.files import load_calibration

        params = load_calibration(args.calibration).apply(params)
    return params
