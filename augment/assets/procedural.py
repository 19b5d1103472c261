"""Procedural cars: a lofted, curved body with a glass greenhouse, wheels in arches, lights and trim,
the details a camera sees at 10-40 m (panel gaps, mirrors, handles, wipers, a slatted grille, recessed
lamps, brake discs, number plates) and an interior behind glass that lets it be seen.

The body is a loft along x of rounded cross-sections (superellipses in y-z whose width narrows
above the belt line: the "tumblehome"), between a side-profile roof curve ``z_top(x)`` and an
underbody curve ``z_bot(x)`` that rises into wheel arches; its plan-view width rounds off at both
ends, closing the surface.  Materials are assigned per face from its position and normal
(windscreen / side windows / rear window with pillars in between, bumpers, grille, head and tail
lights).  Wheels are revolved tyre profiles with a spoked rim cap.  Output is an :class:`Asset` in
the object frame (x front, y left, z up, metres, origin at the bottom centre, tyres touching z = 0).

Random draws: the body, its dimensions and the paint come from the stream ``[seed, 0x5CA4]`` (as before
the details existed, so a seed keeps its body and paint); every detail draw (glass tint, interior
colour, chrome, plate characters, dirt) from its own stream ``[seed, 0xDE7A]``.
"""

from __future__ import annotations

import dataclasses

import numpy as np

from .asset import Asset, Material
from .car_body import BODY_SPECS, BODY_WEIGHTS, N_SLOTS, BodySpec, body_part, jitter_spec
from .car_details import (BodySurface, door_handle_parts, grille_parts, lamp_parts, mirror_parts,
                          paint_over_loft_lamps, plate_parts, wiper_parts)
from .car_interior import interior_parts
from .car_paint import MAX_PAINT_ALBEDO, check_paint_region, paint_palette, srgb_to_linear
from .car_wheels import wheel_parts, wheel_well_parts
from .mesh_parts import MeshPart, merge_parts
from .number_plates import PlateStyle, anonymised_plate_rgb, car_plate_style, check_plate_style, plate_style_for_location
from .validate import validate_asset

MIRROR_OUT_M = 0.04  # how far the mirrors reach beyond the body's widest point (both inside the box)


def procedural_car_variants() -> tuple[str, ...]:
    """Names of the body types :func:`procedural_car` builds."""
    return tuple(BODY_SPECS)


# The paint palette (regional colour-family shares from published colour-popularity reports) is
# :mod:`.car_paint`; "metallic" is the share of the base coat that is aluminium flakes (``Material.flake``), not
# the UE4 metallic of a bare metal surface (see :func:`_materials`).


GLASS_FACE_REFLECTANCE = 0.04  # one air-glass face at normal incidence (n ~1.5)


def pane_specular(tint: np.ndarray, opacity: float) -> float:
    """UE4 specular (F0 / 0.08) of a glass pane drawn as one surface: the reflections of both its faces,
    ``R + R (1 - R)^2 T^2`` at normal incidence (R one face's, T the pane's one-way transmission
    ``(1 - opacity) sqrt(tint)`` as the renderer applies it): ~5.4 % for the clear front glass, ~4.1 % for
    privacy glass, against the 4 % of one face (clear windows reflected the sky a third too weakly)."""
    R = GLASS_FACE_REFLECTANCE
    T = (1.0 - float(opacity)) * float(np.sqrt(np.mean(np.clip(tint, 0.0, 1.0))))
    return float((R + R * (1.0 - R) ** 2 * T**2) / 0.08)


# ----------------------------------------------------------------------------- public entry point


def procedural_car(seed: int, body: str | None = None, paint: tuple | None = None, plate_style: str = "eu",
                   paint_region: str = "global", anonymised_plates: bool = False,
                   paint_weights: tuple[float, ...] | None = None) -> Asset:
    """A plausible car mesh, deterministic for ``seed``.

    Args:
        seed: random seed (body choice when ``body`` is None, dimension jitter, paint; the details draw
            from their own stream, see the module docstring).
        body: one of :func:`procedural_car_variants` (``sedan``, ``hatchback``, ``suv``, ``van``) or None.
        paint: optional linear RGB (3,) paint colour in [0, 1], or (r, g, b, metallic): metallic is the share of
            the base coat that is metallic flakes (the material's ``flake``; its UE4 metallic stays 0).
        plate_style: number plates and driving side: ``sg`` (right-hand drive), ``us`` or ``eu``
            (:func:`~.number_plates.plate_style_for_location` maps a nuScenes location to one).
        paint_region: whose colour popularity the paint is drawn from: ``global``, ``asia_pacific``,
            ``north_america`` or ``europe`` (:func:`~.car_paint.paint_region_for_location` maps a location).
        anonymised_plates: plates without characters, of the plate's mean colour (as the blurred plates of
            nuScenes' images); False: readable characters.
        paint_weights: the draw's weight of every shade of ``paint_palette(paint_region)`` (same order, >= 0,
            any sum > 0) instead of the region's: the paint mix of the scene's own cars
            (:func:`~.scene_paint.scene_paint_mix`); None: the region's table.

    Returns:
        An :class:`Asset` (category ``vehicle.car``), object frame (x front, y left, z up, metres),
        origin at the bottom centre; the tyres touch z = 0; the mirrors reach the box's sides.
        About 18.3-19.5 k triangles.
    """
    groups, materials, name = _build(seed, body, paint, plate_style, paint_region, anonymised_plates, paint_weights)
    parts = [p for group in groups.values() for p in group]
    vertices, faces, face_material = merge_parts(parts)

    # Origin at the bottom centre of the box, tyres on z = 0.
    lo, hi = vertices.min(axis=0), vertices.max(axis=0)
    vertices = vertices - np.array([(lo[0] + hi[0]) / 2, (lo[1] + hi[1]) / 2, lo[2]])
    normals = np.concatenate([p.normals for p in parts])
    asset = Asset(
        name=name, vertices=vertices, faces=faces, face_material=face_material, materials=materials,
        vertex_normals=normals, uv=None, category="vehicle.car",
    )
    return validate_asset(asset)


def procedural_car_parts(seed: int, body: str | None = None, paint: tuple | None = None, plate_style: str = "eu",
                         paint_region: str = "global", anonymised_plates: bool = False) -> dict[str, list[MeshPart]]:
    """The parts of :func:`procedural_car` (same arguments) by group, before centring: ``body`` (the
    shell), ``lenses``, ``wheels``, ``exterior`` (grille slats, mirrors, handles, wipers), ``plates``
    and ``interior``; the car's vertices are their union shifted to the box's bottom centre."""
    return _build(seed, body, paint, plate_style, paint_region, anonymised_plates)[0]


def _build(seed: int, body: str | None, paint: tuple | None, plate_style: str, paint_region: str = "global",
           anonymised_plates: bool = False, paint_weights: tuple[float, ...] | None = None
           ) -> tuple[dict[str, list[MeshPart]], tuple[Material, ...], str]:
    """(parts by group, material table, asset name) of :func:`procedural_car`."""
    style = car_plate_style(plate_style, seed)
    check_paint_region(paint_region)
    rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0x5CA4])
    names = list(BODY_SPECS)
    if body is None:
        w = np.array([BODY_WEIGHTS[n] for n in names])
        body = names[int(rng.choice(len(names), p=w / w.sum()))]
    else:
        rng.random()  # keep the stream aligned with the body=None case
    if body not in BODY_SPECS:
        raise ValueError(f"procedural_car: unknown body {body!r}; expected one of {', '.join(names)}")
    spec = jitter_spec(BODY_SPECS[body](), rng)
    detail_rng = np.random.default_rng([int(seed) & 0xFFFFFFFF, 0xDE7A])
    materials, paint_name, looks = _materials(rng, detail_rng, paint, body, style, paint_region, anonymised_plates,
                                              paint_weights)
    groups = _car_parts(spec, style, looks, detail_rng, anonymised_plates)
    return groups, materials, f"procedural-{body}-{seed}-{paint_name.replace(' ', '_')}"


def _car_parts(spec: BodySpec, style: PlateStyle, looks: dict, rng: np.random.Generator,
               anonymised_plates: bool = False) -> dict[str, list[MeshPart]]:
    """Every mesh part of the car by group: the body (a little narrower than ``spec.width`` so the
    mirrors fit in the box), lamp lenses, wheels and wells, exterior details, plates and the interior.
    The wheels keep ``spec.width``'s track: their outer faces stand about flush with the body's sides."""
    shell = dataclasses.replace(spec, width=spec.width - 2 * MIRROR_OUT_M)
    body = paint_over_loft_lamps(body_part(shell))
    surface = BodySurface(body)
    lenses = lamp_parts(surface, shell)
    exterior = (grille_parts(surface, shell, looks["chrome"]) + mirror_parts(shell, 0.5 * spec.width, looks["mirror_paint"])
                + door_handle_parts(shell, looks["chrome"]) + wiper_parts(surface, shell, style.right_hand_drive))
    return {
        "body": [body], "lenses": lenses, "wheels": wheel_parts(spec) + wheel_well_parts(shell), "exterior": exterior,
        "plates": plate_parts(surface, shell, style, rng, anonymised_plates),
        "interior": interior_parts(shell, style.right_hand_drive),
    }


# ----------------------------------------------------------------------------- materials


def _materials(rng: np.random.Generator, detail_rng: np.random.Generator, paint: tuple | None, body: str,
               style: PlateStyle | None = None, paint_region: str = "global", anonymised_plates: bool = False,
               paint_weights: tuple[float, ...] | None = None) -> tuple[tuple[Material, ...], str, dict]:
    """The material table in slot order (:mod:`.car_body`), the paint's name and the detail choices.

    ``rng`` draws exactly what it drew before the details existed (paint, roughness, glass opacity and
    tint, dark rims: the last two are no longer used but keep the stream); ``detail_rng`` the rest.
    """
    palette = paint_palette(paint_region)
    weights = np.array([p[3] for p in palette])
    if paint_weights is not None:
        w = np.asarray(paint_weights, dtype=np.float64).ravel()
        if w.shape != weights.shape or not np.all(np.isfinite(w)) or w.min() < 0 or w.sum() <= 0:
            raise ValueError(f"procedural_car: paint_weights must be {len(weights)} finite weights >= 0 with a "
                             f"positive sum (one per shade of paint_palette), got {len(w)} values")
        weights = w
    idx = int(rng.choice(len(palette), p=weights / weights.sum()))
    name, color, metallic, _ = palette[idx]
    color = np.clip(color * rng.uniform(0.93, 1.07), 0.0, 1.0)  # small per-car variation
    color = color * min(1.0, MAX_PAINT_ALBEDO / max(float(color.max()), 1e-9))  # no paint brighter (hue kept)
    if paint is not None:
        p = np.asarray(paint, dtype=np.float64).ravel()
        if p.size not in (3, 4) or not np.all(np.isfinite(p)) or p.min() < 0 or p[:3].max() > 1:
            raise ValueError(f"procedural_car: paint must be linear (r, g, b[, metallic]) in [0, 1], got {paint!r}")
        color, name = p[:3].copy(), "custom"
        metallic = float(p[3]) if p.size == 4 else 0.3
    paint_rough = float(rng.uniform(0.30, 0.45))
    rng.uniform(0.30, 0.50)  # the old glass opacity draw (stream kept)
    rng.uniform(0.8, 1.2)  # the old glass tint draw
    rim_dark = rng.random() < 0.25

    # Detail stream.  Glass: transmission through it is (1 - opacity)(1 - F) sqrt(base_color) in the
    # renderer; the windscreen and front side windows pass ~60-65 % at normal incidence, the rear
    # glass of many SUVs / vans (and some cars) is privacy-tinted (~15-30 %).  The glass's own diffuse,
    # base_color x opacity, stays ~0.02-0.03.
    d = detail_rng
    front_tint = np.array([0.40, 0.47, 0.45]) * d.uniform(0.92, 1.08)
    privacy = d.random() < (0.6 if body in ("suv", "van") else 0.2)
    rear_tint = np.array([0.055, 0.065, 0.065]) * d.uniform(0.8, 1.3) if privacy else front_tint
    # Metallic paint is a dielectric base coat with aluminium flakes in it, under the clear coat: the palette's
    # metallic is the flakes' share of the base coat (the flake lobe: rough, energy-conserving, base-coloured),
    # not the UE4 metallic of bare metal.  That lobe (single scattering, the analytic-light Smith k, no
    # multiple-scattering term) has a directional albedo of only 0.29 / 0.36 / 0.46 for silver (0.48) at
    # n.v 0.2 / 0.5 / 1.0 (the flakes: 0.53 / 0.51 / 0.50 with the 4 % specular; roofs and sides at 10-40 m
    # are seen at n.v ~0.1-0.6), so silver, grey and black-metallic cars rendered darker than their colour
    # (silver in scene-0916's overcast: side panels 28 %, roofs 37 % below a Lambertian of the same colour).
    flake = float(np.clip(metallic, 0.0, 1.0))
    dirt = float(d.uniform(0.0, 1.0)) ** 2
    lower = np.clip(color * (1.0 - 0.18 * dirt) + dirt * 0.02 * np.array([0.9, 0.8, 0.6]), 0.0, 1.0)
    chrome = bool(d.random() < 0.3)
    mirror_paint = bool(d.random() < 0.75)
    beige = d.random() < 0.2
    seat_rgb = (np.array([0.20, 0.16, 0.11]) if beige else np.array([0.035, 0.035, 0.038])) * d.uniform(0.8, 1.2)
    brake_rgb = np.array([0.30, 0.29, 0.28]) * d.uniform(0.8, 1.1)
    st = style or check_plate_style("eu")
    plate_rgb = ([anonymised_plate_rgb(st, rear) for rear in (False, True)] if anonymised_plates
                 else [np.array(st.front_rgb), np.array(st.rear_rgb)])
    mats = [
        Material("paint", base_color=color, metallic=0.0, roughness=paint_rough, clearcoat=1.0, flake=flake),
        Material("glass", base_color=front_tint, metallic=0.0, roughness=0.05, specular=pane_specular(front_tint, 0.06),
                 opacity=0.06),
        # Black trim and tyres as a street sees them: weathered, textured plastic and sidewalls under road dust
        # (albedo ~0.04, a soft sheen), not new black (0.02-0.025, matte: under the car's own shadow it rendered
        # at L* < 14 where the real cars of scene-0916 have their 5th percentile at L* ~15-22).
        Material("trim", base_color=np.array([0.040, 0.040, 0.042]), metallic=0.0, roughness=0.6),
        # Rubber's refractive index ~1.5 reflects 4 % at normal incidence (UE4 specular 0.5; 0.3 was 2.4 %).
        Material("tyre", base_color=np.array([0.035, 0.035, 0.034]), metallic=0.0, roughness=0.65, specular=0.5),
        # Alloy wheels are painted: silver (or dark) flake paint under a clear coat, like the body's metallic
        # paint (a bare-metal lobe rendered them at L* ~30, reflecting the road; real ones look light grey).
        Material("rim", base_color=np.array([0.12, 0.12, 0.13]) if rim_dark else np.array([0.62, 0.62, 0.64]),
                 metallic=0.0, roughness=0.3, clearcoat=1.0, flake=0.7),
        # A headlamp's lens is clear polycarbonate: its own diffuse (base x opacity) 0.07, not the milky 0.24 of
        # opacity 0.3 (the lamps read as white plastic), so the reflector behind it shows (issue #20).
        Material("headlight", base_color=np.array([0.80, 0.82, 0.84]), metallic=0.0, roughness=0.04, opacity=0.09,
                 emission=np.array([0.03, 0.03, 0.03])),
        Material("taillight", base_color=np.array([0.50, 0.010, 0.015]), metallic=0.0, roughness=0.06, opacity=0.6),
        Material("glass_rear", base_color=rear_tint, metallic=0.0, roughness=0.05,
                 specular=pane_specular(rear_tint, 0.35 if privacy else 0.06), opacity=0.35 if privacy else 0.06),
        Material("gap", base_color=np.array([0.006, 0.006, 0.006]), metallic=0.0, roughness=0.9, specular=0.2),
        Material("paint_lower", base_color=lower, metallic=0.0, roughness=min(paint_rough + 0.12 * dirt, 0.6),
                 clearcoat=1.0 - 0.4 * dirt, flake=flake),
        Material("plate_front", base_color=plate_rgb[0], roughness=0.45, retroreflective=0.3),
        Material("plate_rear", base_color=plate_rgb[1], roughness=0.45, retroreflective=0.3),
        Material("plate_ink", base_color=np.array(st.ink_rgb), roughness=0.5),
        Material("plate_band", base_color=np.array(st.band_rgb or st.ink_rgb), roughness=0.5),
        Material("interior", base_color=seat_rgb, roughness=0.85, specular=0.3),
        Material("dashboard", base_color=np.array([0.022, 0.022, 0.024]), roughness=0.7, specular=0.35),
        Material("chrome", base_color=np.array([0.80, 0.80, 0.82]), metallic=1.0, roughness=0.15),
        # Vacuum-metallised reflector: a near mirror (roughness 0.1, the shader's mirror term in full; 0.3 was a
        # blurred grey).
        Material("lamp_reflector", base_color=np.array([0.85, 0.85, 0.86]), metallic=1.0, roughness=0.1),
        Material("brake_disc", base_color=brake_rgb, metallic=1.0, roughness=0.45),
    ]
    if len(mats) != N_SLOTS:
        raise RuntimeError(f"procedural_car: {len(mats)} materials for {N_SLOTS} slots")
    return tuple(mats), name, {"chrome": chrome, "mirror_paint": mirror_paint}


__all__ = ["pane_specular", "paint_palette", "plate_style_for_location", "procedural_car", "procedural_car_parts",
           "procedural_car_variants", "srgb_to_linear"]
