"""The ``streetaug`` command line: a thin shell over the library API.

Exit codes: 0 success, 1 bad input or runtime errors (one line on stderr; the traceback only with
``--debug``), 2 bad arguments (click usage errors), 3 a batch finished but some images failed.
"""

from __future__ import annotations

from pathlib import Path

import click
import numpy as np

from streetaug.augment.core.paths import refuse_output_inside, refuse_overwriting_inputs

from .common import (
    FOV_RANGE,
    INTRINSICS_CHECK,
    LEVEL_HELP,
    LIGHT_LEVELS,
    POSE_CHECK,
    POSITION_CHECK,
    YAW_SIGMA_RANGE,
    asset_options,
    camera_view,
    dataset_options,
    intrinsics_option,
    library_imports,
    limit_options,
    open_dataset,
    parse_floats,
    parse_intrinsics,
    render_options,
    resolve_sample,
    runtime_errors,
)
from .lazy_group import LazyGroup

# Commands in their own modules (one command or a few each), imported only when looked up: running one
# command does not import the others, and none imports its library code (torch, scipy, the batch
# machinery) until it runs.
LAZY_COMMANDS = {
    "batch": "streetaug.cli.batch:batch",
    "bench": "streetaug.cli.bench:bench",
    "merge": "streetaug.cli.batch:merge",
    "stability": "streetaug.cli.stability:stability",
    "train-light": "streetaug.cli.train:train_light",
    "train-sky": "streetaug.cli.train:train_sky",
}


@click.group(cls=LazyGroup, lazy_commands=LAZY_COMMANDS,
             context_settings={"help_option_names": ["-h", "--help"], "max_content_width": 100})
@click.version_option(package_name="streetaug")
def main() -> None:
    """streetaug: insert physically lit, shadowed 3D cars into driving datasets, with exact 3D labels.

    \b
    Quick start (bundled sample scenes):
      streetaug insert --scene sample-sunny --out out/sunny
      streetaug predict-light --scene sample-lowsun --out out/light
      streetaug batch --out out/dataset

    \b
    Exit codes: 0 success; 1 bad input or a runtime error (one line on stderr, the
    traceback with --debug); 2 bad arguments (also non-finite or out-of-range numbers);
    3 a batch finished but some images failed (counted in summary.json, reasons in
    OUT/augment_log.jsonl).
    """


# ----------------------------------------------------------------------------- predict-light


@main.command("predict-light")
@dataset_options
@click.option("--image", type=click.Path(dir_okay=False, path_type=Path), help="A single image (no metadata).")
@click.option("--fov-deg", type=FOV_RANGE, help="Horizontal field of view of --image, degrees (0-180).")
@click.option("--intrinsics", callback=INTRINSICS_CHECK, help="fx,fy,cx,cy of --image (pixel centres at integers).")
@click.option("--at", "at", callback=POSITION_CHECK, help="X,Y,Z (camera frame, metres): point of the local "
              "environment map (default: the ground point 15 m straight ahead).")
@click.option("--level", type=click.Choice(LIGHT_LEVELS), default="auto", show_default=True, help=LEVEL_HELP)
@click.option("--previous-keyframe", is_flag=True, help="Also use the sample's previous keyframe (its cameras "
              "saw what is now behind and above): L2/L3 fill what the instant's cameras left open (on scene-0916 "
              "+0.06 dB six-view, +35 % lighting time). A scene's first sample has none: it is lit without.")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path), help="Output folder.")
@click.option("--debug", is_flag=True, help="Show tracebacks.")
@limit_options
@runtime_errors
def predict_light(dataroot, version, scene, sample_token, camera, image, fov_deg, intrinsics, at, level,
                  previous_keyframe, out, debug):
    """Estimate the scene's HDR lighting; write lighting.json, envmap_camera.exr and preview.png.

    \b
    Examples:
      streetaug predict-light --scene sample-sunny --out out/light
      streetaug predict-light --dataroot ../shared/data/nuscenes-real --version v1.0-mini \\
          --scene scene-0061 --camera CAM_FRONT --out out/light-real
      streetaug predict-light --image photo.jpg --fov-deg 70 --out out/light-photo
    """
    with library_imports():
        from streetaug.augment.core import read_image_rgb
        from streetaug.augment.lighting import estimate_lighting_from_image, write_lighting_outputs
        from streetaug.augment.lighting.api import estimate_instant_lighting

    at_cam = parse_floats(at, 3, "--at")
    if image is not None and previous_keyframe:
        raise click.UsageError("--previous-keyframe needs a dataset sample, not --image")
    if image is not None:
        if fov_deg is None and intrinsics is None:
            raise click.UsageError("--image needs --fov-deg F or --intrinsics fx,fy,cx,cy")
        refuse_overwriting_inputs(out, ["lighting.json", "envmap_camera.exr", "preview.png"], {"--image": image})
        rgb = read_image_rgb(image)
        K = intrinsics_option(intrinsics, fov_deg, rgb.shape[1], rgb.shape[0])
        estimate = estimate_lighting_from_image(rgb, K, level=level, for_map=True)
        query = at_cam or [0.0, 1.5, 15.0]
    else:
        reader = open_dataset(dataroot, version)
        refuse_output_inside(out, reader.dataroot)  # never write into the source (nor contain it)
        sample = reader.sample(resolve_sample(reader, scene, sample_token))
        view = camera_view(sample, camera)
        rgb = view.image
        if at_cam is None:
            normal, offset = view.ego_ground_plane_cam
            # The ground point straight ahead at 15 m depth: on the plane n . p + d = 0 with p = (0, y, 15).
            y = -(offset + normal[2] * 15.0) / normal[1] if abs(normal[1]) > 1e-6 else 1.5
            at_cam = [0.0, float(y), 15.0]
        query = at_cam
        previous = None
        if previous_keyframe:
            prev_token = reader.get("sample", sample.token).get("prev", "")
            if prev_token:
                previous = reader.sample(prev_token)
            else:
                click.echo(f"sample {sample.token} is its scene's first: no previous keyframe, lit from this one alone")
        estimate = estimate_instant_lighting(sample, view.channel, level, np.asarray(query, dtype=float),
                                             for_map=True, previous=previous)
    write_lighting_outputs(estimate, out, rgb, query_point_cam=np.asarray(query, dtype=float))
    click.echo(f"wrote {out}/lighting.json, envmap_camera.exr, preview.png "
               f"(sun: {estimate.sun_source}, visibility {estimate.sun_visibility:.2f}, level {estimate.level})")


# ----------------------------------------------------------------------------- insert


@main.command("insert")
@dataset_options
@asset_options
@render_options
@click.option("--level", type=click.Choice(LIGHT_LEVELS), default="auto", show_default=True, help=LEVEL_HELP)
@click.option("--n-objects", type=click.IntRange(1, 8), default=1, show_default=True, help="Objects per image.")
@click.option("--yaw-sigma", type=YAW_SIGMA_RANGE, default=3.0, show_default=True,
              help="Yaw noise (deg, 0-180) around the ego heading: 3 realistic, 15 augmentation.")
@click.option("--image", type=click.Path(dir_okay=False, path_type=Path), help="Image form: the input image.")
@click.option("--intrinsics", callback=INTRINSICS_CHECK, help="Image form: fx,fy,cx,cy.")
@click.option("--depth", type=click.Path(dir_okay=False, path_type=Path), help="Image form: metric depth (.exr|.npy).")
@click.option("--envmap", type=click.Path(dir_okay=False, path_type=Path), help="Image form: camera-frame env map (.exr).")
@click.option("--pose-camera", callback=POSE_CHECK,
              help="Image form: X,Y,Z,YAW_DEG (box bottom centre, camera frame; |X|, |Y|, |Z| <= 10 km).")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path), help="Output folder.")
@click.option("--explain", is_flag=True, help="Dataset form: also write placement_bev.png (candidates and the "
              "rules that rejected them, over the map, LiDAR and boxes).")
@click.option("--debug", is_flag=True, help="Also write mask.png and shadow.exr; show tracebacks.")
@limit_options
@runtime_errors
def insert(dataroot, version, scene, sample_token, camera, asset, assets_dir, asset_front, asset_length, classes,
           class_weights, class_rules, class_sizes, quality, seed, ev, match_camera, level, n_objects, yaw_sigma, image, intrinsics, depth, envmap, pose_camera, out, explain,
           debug):
    """Insert a car into one image; write image.png|jpg and labels.json.

    \b
    Dataset form (a nuScenes sample; without --dataroot, a bundled sample scene):
      streetaug insert --scene sample-sunny --out out/sunny
      streetaug insert --scene scene-0061 --dataroot ../shared/data/nuscenes-real \\
          --version v1.0-mini --camera CAM_FRONT --out out/real
    Image form (any image with depth, a camera-frame env map and a pose):
      streetaug insert --image img.png --intrinsics 1266,1266,816,491 --depth depth.exr \\
          --envmap env.exr --asset car.glb --pose-camera 0.5,1.5,15,90 --out out/img
    """
    # Deferred: the pipeline and the assets load scipy (torch only if the sky network runs); `--help` must not.
    with library_imports():
        from streetaug.augment.assets.classes import ClassMix
        from streetaug.augment.assets.scene_paint import scene_paint_mix
        from streetaug.augment.assets.select import load_asset_options, select_assets
        from streetaug.augment.pipeline import (InsertOptions, check_image_input, insert_image_to_files,
                                                insert_view_to_files, item_seed)

    if asset is not None and (classes or class_weights):
        raise click.UsageError("--classes/--class-weights choose procedural objects or --assets files by class; "
                               "--asset FILE is one object: give one or the other")
    class_mix = ClassMix.parse(classes, class_weights)
    options = InsertOptions(quality=quality, level=level, seed=seed, n_objects=n_objects, yaw_sigma_deg=yaw_sigma, ev=ev,
                            match_camera=match_camera, class_rules=str(class_rules) if class_rules else None)
    if image is not None:
        missing = [n for n, v in [("--intrinsics", intrinsics), ("--depth", depth), ("--envmap", envmap),
                                  ("--asset", asset), ("--pose-camera", pose_camera)] if v is None]
        if missing:
            raise click.UsageError(f"the image form of insert also needs {', '.join(missing)}")
        check_image_input(image, options)  # a huge image is refused at once, before the asset is loaded
        refuse_overwriting_inputs(out, ["image.png", "image.jpg", "labels.json", "mask.png", "shadow.exr"],
                                  {"--image": image, "--depth": depth, "--envmap": envmap, "--asset": asset})
        result, path = insert_image_to_files(image, parse_intrinsics(intrinsics), depth, envmap,
                                             load_asset_options(asset, asset_front, asset_length),
                                             parse_floats(pose_camera, 4, "--pose-camera"), options, out, debug)
    else:
        if scene is None and sample_token is None:
            raise click.UsageError("give --scene NAME_OR_TOKEN (dataset form) or --image IMG (image form)")
        reader = open_dataset(dataroot, version)
        refuse_output_inside(out, reader.dataroot)  # never write into the source (nor contain it)
        sample = reader.sample(resolve_sample(reader, scene, sample_token))
        view = camera_view(sample, camera)
        # the paint of the sample's own cars, seen by all its cameras (as `batch` measures it: the same cars)
        paint = scene_paint_mix(sample) if asset is None and assets_dir is None else None
        assets = select_assets(item_seed(seed, "asset", sample.token, camera), n_objects, asset, assets_dir,
                               asset_front, asset_length, class_mix, class_sizes=class_sizes,
                               location=sample.location, paint_weights=paint)
        result, path = insert_view_to_files(sample, view, assets, options, out, debug, explain)
    if result.skipped_reason:
        click.echo(f"no object inserted: {result.skipped_reason} (image copied unchanged to {path})")
    else:
        click.echo(f"wrote {path} and {out}/labels.json: {len(result.objects)} object(s), "
                   f"{result.timing_s['total']:.2f} s")


# ----------------------------------------------------------------------------- make-samples


@main.command("class-sizes")
@click.option("--dataroot", "dataroots", required=True, multiple=True,
              type=click.Path(file_okay=False, exists=True, path_type=Path),
              help="nuScenes dataroot(s) to measure (repeat the option to pool several).")
@click.option("--version", required=True, help="Table folder in each dataroot, e.g. v1.0-trainval.")
@click.option("--out", required=True, type=click.Path(dir_okay=False, path_type=Path),
              help="The class-sizes table to write (JSON; pass it to insert/batch --class-sizes).")
@click.option("--debug", is_flag=True, help="Show tracebacks.")
@runtime_errors
def class_sizes(dataroots, version, out, debug):
    """Measure box sizes per category from annotations: the table procedural objects are built to.

    \b
    Example:
      streetaug class-sizes --dataroot /data/nuscenes --version v1.0-trainval --out sizes.json
      streetaug batch ... --classes bus,trailer --class-sizes sizes.json
    """
    from streetaug.augment.assets.class_sizes import class_sizes_document
    from streetaug.augment.core import write_json_atomic
    from streetaug.datasets.box_statistics import measure_box_sizes

    dirs = [Path(d) / version for d in dataroots]
    measured = measure_box_sizes(dirs)
    doc = class_sizes_document(measured, [str(d.resolve()) for d in dirs])
    write_json_atomic(out, doc)
    for category, e in doc["categories"].items():
        click.echo(f"{category:32s} {e['source']:15s} {e['n_instances']:6d} instances {e['n_boxes']:7d} boxes  "
                   f"mean wlh {', '.join(f'{v:.2f}' for v in e['mean_wlh'])}")
    click.echo(f"wrote {out}")


@main.command("make-samples")
@click.option("--out", required=True, type=click.Path(file_okay=False, path_type=Path), help="Output dataroot.")
@click.option("--scenes", default=None, help="Comma-separated scene names (default: all).")
@click.option("--sequence", is_flag=True, help="Make the sequence scene (v1.0-sequence: keyframes 0.5 s apart, "
              "the ego driving) instead of the one-keyframe sample scenes.")
@click.option("--sweeps", is_flag=True, help="With --sequence: also render the camera (12 Hz) and LiDAR (20 Hz) "
              "sweep files (the tables list them either way).")
@click.option("--width", type=int, default=None, help="Image width [default: 1600; 800 with --sequence].")
@click.option("--height", type=int, default=None, help="Image height [default: 900; 450 with --sequence].")
@click.option("--seed", type=int, default=0, show_default=True)
@click.option("--debug", is_flag=True, help="Show tracebacks.")
@runtime_errors
def make_samples(out, scenes, sequence, sweeps, width, height, seed, debug):
    """Generate the procedural sample scenes (nuScenes format + ground-truth lighting).

    \b
    Examples (regenerate the bundled scenes byte-identically):
      streetaug make-samples --out examples/nuscenes-samples
      streetaug make-samples --sequence --out examples/nuscenes-sequence   (add --sweeps for the sweep files)
    """
    if sweeps and not sequence:
        raise click.UsageError("--sweeps needs --sequence (only the sequence scene has sweeps)")
    if sequence and scenes:
        raise click.UsageError("--scenes selects sample scenes; the sequence (--sequence) is one scene")
    if sequence:
        from streetaug.augment.scenegen.sequence import make_sequence_scene  # deferred: scipy, slow for `--help`

        paths = make_sequence_scene(out, sweeps=sweeps, width=800 if width is None else width,
                                    height=450 if height is None else height, seed=seed)
        click.echo(f"wrote the sequence scene into {out} ({len(paths)} files{', sweeps included' if sweeps else ''})")
        return
    from streetaug.augment.scenegen.make import make_sample_scenes  # deferred: scipy, slow for `--help`

    names = [s.strip() for s in scenes.split(",")] if scenes else None
    paths = make_sample_scenes(out, names=names, width=1600 if width is None else width,
                                height=900 if height is None else height, seed=seed)
    click.echo(f"wrote {len(paths)} scene(s) into {out}")


if __name__ == "__main__":
    main()
