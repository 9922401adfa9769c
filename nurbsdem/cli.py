"""The ``nurbsdem`` command line (placeholder: commands are being added)."""
from __future__ import annotations

import click

from . import __version__


@click.group()
@click.version_option(__version__, prog_name="nurbsdem")
def main() -> None:
    """nurbsdem: DEM with exact convex NURBS particles."""
