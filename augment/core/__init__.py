"""The leaf core of streetaug: every convention, the error types, I/O at the edges, rays and depth.

It imports nothing else of the project; everything else may import it. The conventions, one module each:

* ``frames``: the frames (camera OpenCV, ego/object and global nuScenes; a diagram in its docstring),
  quaternions ``[w, x, y, z]``, rigid transforms ``T_a_from_b`` (chains read right to left),
  object poses in the camera (``--pose-camera``).
* ``camera``: :class:`PinholeCamera` (pixel centres at integer coordinates), projection, pixel rays.
* ``envmap``: the camera-frame and world equirectangular maps and their one bilinear lookup.
* ``response``: the camera response (LDR <-> linear HDR, gamma 2.2 + soft clip tau = 0.95) and luminance.
* ``errors``: :class:`InputError`, :class:`ConventionError`, :func:`check_shape`, :func:`check_rays`.
* ``io``: atomic writes, images, EXR, JSON.
* ``raycast`` (embree; import it directly) and ``depth`` (the one LiDAR-to-camera depth; import it directly).

The light modules are re-exported here: ``from streetaug.augment.core import quat_to_rotation, PinholeCamera``.
"""

from .camera import (PinholeCamera, box_corners_cam, box_rect_px, intrinsics_from_fov, pixel_rays, project_points,
                     scale_intrinsics, unproject_depth)
from .envmap import (camera_dir_to_lonlat, camera_envmap_directions, equirect_pixel_lonlat, equirect_solid_angles,
                     lonlat_to_camera_dir, lonlat_to_uv, lonlat_to_world_dir, sample_equirect, world_dir_to_lonlat)
from .errors import ConventionError, InputError, check_rays, check_shape
from .frames import (invert_transform, make_transform, pose_camera_to_transform, quat_to_rotation, quat_to_yaw,
                     rotate_vectors, rotation_to_quat, transform_points, transform_to_pose_camera, yaw_to_quat)
from .io import (atomic_path, encode_image_rgb, read_exr, read_image_rgb, read_json, write_bytes_atomic, write_exr,
                 write_image_rgb, write_json_atomic)
from .response import (GAMMA, SATURATION_LDR, SATURATION_RADIANCE, SOFTCLIP_TAU, clipped_to_lower_bound, hdr_to_ldr,
                       hdr_to_ldr_uint8, inverse_softclip, ldr_to_hdr, ldr_uint8_to_hdr, luminance, softclip)

__all__ = [
    "PinholeCamera", "box_corners_cam", "box_rect_px", "intrinsics_from_fov", "pixel_rays", "project_points",
    "scale_intrinsics", "unproject_depth",
    "camera_dir_to_lonlat", "camera_envmap_directions", "equirect_pixel_lonlat", "equirect_solid_angles",
    "lonlat_to_camera_dir", "lonlat_to_uv", "lonlat_to_world_dir", "sample_equirect", "world_dir_to_lonlat",
    "ConventionError", "InputError", "check_rays", "check_shape",
    "invert_transform", "make_transform", "pose_camera_to_transform", "quat_to_rotation", "quat_to_yaw",
    "rotate_vectors", "rotation_to_quat", "transform_points", "transform_to_pose_camera", "yaw_to_quat",
    "atomic_path", "encode_image_rgb", "read_exr", "read_image_rgb", "read_json", "write_bytes_atomic", "write_exr",
    "write_image_rgb", "write_json_atomic",
    "GAMMA", "SOFTCLIP_TAU", "hdr_to_ldr", "hdr_to_ldr_uint8", "inverse_softclip", "ldr_to_hdr", "ldr_uint8_to_hdr",
    "luminance", "softclip", "SATURATION_LDR", "SATURATION_RADIANCE", "clipped_to_lower_bound",
]
