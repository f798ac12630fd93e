"""Batch commands: batch, batch-report."""

from __future__ import annotations

import sys
from pathlib import Path

import click

from vid2sim.cli.group import cli
from vid2sim.cli.options import (
    check_out_dir,
    config_option,
    detector_options,
    echo,
    settings_from,
    show_progress,
)

# --------------------------------------------------------------------------- batch


@cli.command()
@click.argument("manifest")
@click.option("--out", "out_dir", required=True,
              help="Batch folder, a path or an fsspec URL (s3://, gs://): one subfolder per row "
                   "(OUT/<name>/), index.parquet + index.csv, batch.csv, fleet.html.")
@click.option("--engine", type=click.Choice(["local", "ray"]), default="local",
              show_default=True,
              help="local: a process pool on this machine; ray: one Ray task per row on a "
                   "Ray cluster (--address) or a local Ray runtime.")
@click.option("--address", default=None, envvar="RAY_ADDRESS",
              help="Ray cluster to run on (host:port, ray://host:10001, or auto inside a Ray "
                   "job) [env RAY_ADDRESS; default a local Ray runtime].")
@click.option("--jobs", type=click.IntRange(min=1), default=None,
              help="Videos built at once (local default 1; ray default: every free slot of "
                   "the cluster; a local Ray runtime gets jobs x cpus-per-job CPUs).")
@click.option("--cpus-per-job", type=click.IntRange(min=1), default=None,
              help="CPUs of each video's build = its onnxruntime and OpenCV threads (local "
                   "default cores / jobs, ray default 1).")
@click.option("--max-retries", type=click.IntRange(min=0), default=2, show_default=True,
              help="Further attempts at a video whose worker process or node died.")
@detector_options
@click.option("--offline", is_flag=True, help="Never download a map.")
@click.option("--retry-failed", is_flag=True,
              help="Rebuild rows the index records as failed (default: keep their error "
                   "unless their inputs changed).")
@config_option
@click.pass_context
def batch(ctx: click.Context, manifest: str, out_dir: str, engine: str, address: str | None,
          jobs: int | None, cpus_per_job: int | None, max_retries: int, offline: bool,
          retry_failed: bool, **detector) -> None:
    """Build one scenario per row of MANIFEST, a CSV with a header: video (required), name,
    gps, map, camera, detections, keyframes, fps, gps_offset_s, ego_speed_mps (paths relative
    to the manifest, or URLs). Rows already built from the same inputs are skipped; exit 1 if
    a row failed."""
    from vid2sim.app.batch import run_batch

    if "://" not in out_dir:
        check_out_dir(Path(out_dir))
    settings = settings_from(**detector, allow_download=not offline)
    summary = run_batch(manifest, out_dir, settings, engine=engine, jobs=jobs,
                        cpus_per_job=cpus_per_job, max_retries=max_retries, address=address,
                        retry_failed=retry_failed,
                        progress=show_progress() and sys.stderr.isatty(), report=echo)
    echo(summary.summary())
    if summary.failed:
        ctx.exit(1)


@cli.command("batch-report")
@click.argument("batch_dir")
@click.option("--out", "out_path", default=None,
              help="Page to write (default BATCH_DIR/fleet.html; its links to the rows' "
                   "reports are relative to BATCH_DIR).")
def batch_report(batch_dir: str, out_path: str | None) -> None:
    """Fleet summary of a batch folder as one HTML page: counts by status, commonest errors,
    time per stage, distributions of lead range, time to collision and keyframe F1, and a
    per-video table linking each report.html."""
    from vid2sim.app.batch import write_fleet_report

    echo(f"fleet summary: {write_fleet_report(batch_dir, out_path)}")
