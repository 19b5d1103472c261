"""``streetaug bench``: the speed/accuracy chart (see :mod:`streetaug.augment.evaluation.speed_accuracy`)."""

from __future__ import annotations

import csv
import io
import platform
from pathlib import Path

import click

from .common import _runtime_errors


def _names(value: str, allowed: tuple[str, ...], option: str) -> list[str]:
    names = [v.strip() for v in value.split(",") if v.strip()]
    bad = [n for n in names if n not in allowed]
    if bad or not names:
        raise click.BadParameter(f"expected a comma-separated subset of {', '.join(allowed)}, got {value!r}",
                                 param_hint=option)
    return names


@click.command("bench")
@click.option("--scenes", default="sample-sunny,sample-lowsun,sample-overcast", show_default=True,
              help="Bundled scenes (their true lighting is known).")
@click.option("--seeds", default="0,1", show_default=True, help="Placements per scene (comma-separated seeds).")
@click.option("--levels", default="L0,L1,L2,L3,auto", show_default=True, help="Lighting levels to sweep.")
@click.option("--presets", default="draft,default,high", show_default=True, help="Render presets to sweep.")
@click.option("--small", is_flag=True, help="The CI configuration: one scene, one placement, L0/L1/auto x draft.")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path), help="Output folder.")
@click.option("--debug", is_flag=True, help="Show tracebacks.")
@_runtime_errors
def bench(scenes, seeds, levels, presets, small, out, debug):
    """Sweep lighting levels x render presets on the bundled scenes; chart time vs error.

    Writes speed_accuracy.png (log time vs composite RMSE, Pareto front, auto highlighted),
    speed_accuracy.csv (one row per scene x placement x configuration), speed_accuracy.md (the table)
    and speed_accuracy.json.

    \b
    Examples:
      streetaug bench --out benchmarks/results
      streetaug bench --small --out /tmp/bench
    """
    import os

    from streetaug.augment.evaluation import speed_accuracy as sa
    from streetaug.augment.core import write_bytes_atomic, write_json_atomic
    from streetaug.datasets.bundled import bundled_dataroot

    if small:
        scenes, seeds, levels, presets = "sample-sunny", "0", "L0,L1,auto", "draft"
    from streetaug.augment.scenegen.make import SAMPLE_SCENES

    scene_names = _names(scenes, tuple(SAMPLE_SCENES), "--scenes")
    try:
        seed_list = [int(s) for s in seeds.split(",") if s.strip()]
    except ValueError:
        raise click.BadParameter(f"expected comma-separated integers, got {seeds!r}", param_hint="--seeds") from None
    level_list = _names(levels, sa.LEVELS, "--levels")
    preset_list = _names(presets, sa.PRESETS, "--presets")

    cases = sa.make_cases(bundled_dataroot(), scene_names, seed_list)
    if not cases:
        raise click.ClickException("no placement found in any scene/seed: nothing to measure")
    rows = []
    with click.progressbar(length=len(cases) * len(level_list) * len(preset_list), label="bench") as bar:
        for case in cases:
            for level in level_list:
                for preset in preset_list:
                    rows.append(sa.run_configuration(case, level, preset))
                    bar.update(1)
    table = sa.summarise(rows)
    title = (f"{len(cases)} insertions ({', '.join(scene_names)}); load {os.getloadavg()[0]:.1f} on {os.cpu_count()} "
             f"cores\nreference: high preset under the true local light of the generated street")
    sa.plot_chart(table, out / "speed_accuracy.png", title)
    buf = io.StringIO()
    writer = csv.DictWriter(buf, fieldnames=list(rows[0]))
    writer.writeheader()
    writer.writerows(rows)
    write_bytes_atomic(out / "speed_accuracy.csv", buf.getvalue().encode())
    md = sa.markdown_table(table)
    write_bytes_atomic(out / "speed_accuracy.md", md.encode())
    write_json_atomic(out / "speed_accuracy.json", {
        "schema": "streetaug.speed_accuracy/1", "machine": {"python": platform.python_version(),
                                                           "cpu_count": os.cpu_count(), "load_avg": os.getloadavg()},
        "cases": [{"scene": c.scene, "seed": c.seed} for c in cases], "table": table, "rows": rows,
        "renderer_vs_mitsuba": sa.renderer_reference_rows(Path(__file__).resolve().parents[1] / "benchmarks" / "results"),
    })
    click.echo(md)
    auto = [t for t in table if t["level"] == "auto"]
    for t in auto:
        click.echo(f"auto ({t['config']}): {'on' if t['pareto'] else 'off'} the Pareto front, "
                   f"{t['rmse_above_front']:.2f} RMSE above it")
    click.echo(f"wrote {out}/speed_accuracy.png, .csv, .md, .json")
