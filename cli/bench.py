"""``streetaug bench``: the speed/accuracy chart (see :mod:`streetaug.augment.evaluation.speed_accuracy`)."""

from __future__ import annotations

from pathlib import Path

import click

from .common import runtime_errors


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
@click.option("--class-rules", type=click.Path(dir_okay=False, exists=True, path_type=Path), default=None,
              help="JSON file overriding the per-class placement rules of the cases (as insert's --class-rules).")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path), help="Output folder.")
@click.option("--debug", is_flag=True, help="Show tracebacks.")
@runtime_errors
def bench(scenes, seeds, levels, presets, small, class_rules, out, debug):
    """Sweep lighting levels x render presets on the bundled scenes; chart time vs error.

    Writes speed_accuracy.png (log time vs composite RMSE, Pareto front, auto highlighted),
    speed_accuracy.csv (one row per scene x placement x configuration), speed_accuracy.md (the table)
    and speed_accuracy.json.

    \b
    Examples:
      streetaug bench --out benchmarks/results
      streetaug bench --small --out /tmp/bench
    """
    # Deferred: the sweep loads scipy (torch only if the sky network runs); `streetaug --help` must not.
    from streetaug.augment.evaluation import speed_accuracy as sa
    from streetaug.augment.scenegen.make import SAMPLE_SCENES
    from streetaug.datasets.bundled import bundled_dataroot

    if small:
        scenes, seeds, levels, presets = "sample-sunny", "0", "L0,L1,auto", "draft"
    scene_names = _names(scenes, tuple(SAMPLE_SCENES), "--scenes")
    try:
        seed_list = [int(s) for s in seeds.split(",") if s.strip()]
    except ValueError:
        raise click.BadParameter(f"expected comma-separated integers, got {seeds!r}", param_hint="--seeds") from None
    level_list = _names(levels, sa.LEVELS, "--levels")
    preset_list = _names(presets, sa.PRESETS, "--presets")
    n_steps = len(scene_names) * len(seed_list) * len(level_list) * len(preset_list)  # at most: cases may drop
    with click.progressbar(length=n_steps, label="bench") as bar:
        table = sa.run_bench(bundled_dataroot(), scene_names, seed_list, level_list, preset_list, out,
                             on_step=lambda: bar.update(1), class_rules=str(class_rules) if class_rules else None)
    click.echo(sa.markdown_table(table))
    for t in (t for t in table if t["level"] == "auto"):
        click.echo(f"auto ({t['config']}): {'on' if t['pareto'] else 'off'} the Pareto front, "
                   f"{t['rmse_above_front']:.2f} RMSE above it")
    click.echo(f"wrote {out}/speed_accuracy.png, .csv, .md, .json")
