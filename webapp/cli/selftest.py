"""`illusion-studio selftest`: the generation pipeline against synthetic ground truth."""

from __future__ import annotations

import json

import click

from dataset.selftest import run_selftest

# What a healthy pipeline reaches; a figure beyond these fails the self-test.
LIMITS = {"rectified_epe_illusion_after": 0.5, "stereo_consistency_epe": 1.0}
MIN_PSNR_DB = 30.0


@click.command()
@click.option("--json", "as_json", is_flag=True, help="Print one JSON object.")
@click.option("--seeds", default=3, show_default=True, type=click.IntRange(1, 50), help="Synthetic scenes to use.")
def selftest(as_json: bool, seeds: int) -> None:
    """Rectify fooled disparities, synthesize right views and check them against the exact truth."""
    result = run_selftest(seeds=tuple(range(seeds)))
    failures = [f"{k} {result[k]} > {v}" for k, v in LIMITS.items() if not result[k] <= v]
    if not result["right_view_psnr_db"] >= MIN_PSNR_DB:
        failures.append(f"right_view_psnr_db {result['right_view_psnr_db']} < {MIN_PSNR_DB}")
    result["ok"] = not failures
    if as_json:
        click.echo(json.dumps(result))
    else:
        for key, value in result.items():
            click.echo(f"{key:34} {value}")
    if failures:
        raise click.ClickException("self-test failed: " + "; ".join(failures))
