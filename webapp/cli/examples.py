"""`illusion-studio example-data NAME OUT_DIR`: small real datasets that ship inside pinned packages."""

from __future__ import annotations

from pathlib import Path

import click

EXAMPLES = ("motorcycle",)


@click.command("example-data")
@click.argument("name", type=click.Choice(EXAMPLES))
@click.argument("out_dir", type=click.Path(file_okay=False, path_type=Path))
def example_data(name: str, out_dir: Path) -> None:
    """Write a small real dataset folder that needs no download: motorcycle (Middlebury 2014's Motorcycle as
    scikit-image ships it, 741×500, with ground truth and calibration; read it with --format middlebury)."""
    from dataset.readers.motorcycle import write_motorcycle

    scene = write_motorcycle(out_dir)
    click.echo(f"{scene}: im0.png, im1.png, disp0.pfm, calib.txt (--format middlebury)")
