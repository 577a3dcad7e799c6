"""Oriented boxes drawn with exact pinhole geometry and a z-buffer.

Each visible face is clipped against the near plane, projected through K, filled as a convex
polygon, and textured by the plane-to-image homography H = K [e_s, e_t, X_0] (Hartley &
Zisserman eq. 2.2 / 13.1): every pixel shows the texel its ray hits on the face plane. Its
depth is the ray-plane intersection z = (n . X_0) / (n . K^-1 [u, v, 1]), compared with the
z-buffer, so nearer surfaces hide farther ones whatever the drawing order. Coverage follows the
pixel-centre rule exactly: textures carry a one-texel transparent border and a pixel belongs to
the face iff its bilinearly warped alpha exceeds one half, i.e. its centre maps inside the face.
"""

from __future__ import annotations

import dataclasses

import cv2
import numpy as np

from drivewm.layout.classes import label_id
from drivewm.logs.types import AgentBox

NEAR_M = 0.05
#: Face corners (top-left, top-right, bottom-right, bottom-left seen from outside) as signs of
#: the local box axes (x forward along the length, y left, z up).
FACE_CORNER_SIGNS = {
    "front": ((1, -1, 1), (1, 1, 1), (1, 1, -1), (1, -1, -1)),
    "back": ((-1, 1, 1), (-1, -1, 1), (-1, -1, -1), (-1, 1, -1)),
    "left": ((1, 1, 1), (-1, 1, 1), (-1, 1, -1), (1, 1, -1)),
    "right": ((-1, -1, 1), (1, -1, 1), (1, -1, -1), (-1, -1, -1)),
    "top": ((1, 1, 1), (1, -1, 1), (-1, -1, 1), (-1, 1, 1)),
    "bottom": ((-1, 1, -1), (-1, -1, -1), (1, -1, -1), (1, 1, -1)),
}
FACE_NAMES = tuple(FACE_CORNER_SIGNS)
_SIGNS = np.array([FACE_CORNER_SIGNS[f] for f in FACE_NAMES], np.float64)  # (6, 4, 3)
_NORMALS_LOCAL = np.array([[1, 0, 0], [-1, 0, 0], [0, 1, 0], [0, -1, 0], [0, 0, 1], [0, 0, -1]], np.float64)


@dataclasses.dataclass
class FaceTextures:
    """The six face textures of one box in FACE_NAMES order as RGBA (h + 2, w + 2, 4) uint8 with a
    one-texel border (edge colours, alpha 0), and their inner sizes (6, 2) as (w, h) texels."""

    images: list[np.ndarray]
    sizes: np.ndarray

    @classmethod
    def from_dict(cls, textures: dict[str, np.ndarray]) -> FaceTextures:
        images = []
        for f in FACE_NAMES:
            rgb = cv2.copyMakeBorder(textures[f], 1, 1, 1, 1, cv2.BORDER_REPLICATE)
            alpha = np.zeros(rgb.shape[:2], np.uint8)
            alpha[1:-1, 1:-1] = 255
            images.append(np.dstack([rgb, alpha]))
        sizes = np.array([[textures[f].shape[1], textures[f].shape[0]] for f in FACE_NAMES], np.float64)
        return cls(images, sizes)

    def shaded(self, shades: np.ndarray) -> FaceTextures:
        """The same textures with each face's colour scaled by ``shades`` (6,) (baked lighting)."""
        images = [
            np.dstack([cv2.convertScaleAbs(img[..., :3], alpha=float(k)), img[..., 3]])
            for img, k in zip(self.images, shades)
        ]
        return FaceTextures(images, self.sizes)


@dataclasses.dataclass
class BoxSet:
    """Boxes as arrays: face corners (N, 6, 4, 3) and outward normals (N, 6, 3) in the world frame,
    bounding-sphere centres (N, 3) and radii (N,), each box's face textures and shading (N, 6), and
    the label id (N,) uint8 each box gives its pixels in a label map (drivewm.layout.classes).
    ``interpolation``: how textures are sampled. Bilinear (the default) blends texels, and its alpha
    test follows the pixel-centre rule along the edges while cutting each corner by up to a fifth of
    a texel; nearest (``cv2.INTER_NEAREST``) follows the rule exactly, corners too (solid faces).
    ``front_to_back``: draw the faces nearest first, so that more of the far ones are found hidden
    and skipped (the pixels are the same, but where two faces meet at exactly equal depth)."""

    corners_world: np.ndarray
    normals_world: np.ndarray
    centers: np.ndarray
    radii: np.ndarray
    textures: list[FaceTextures]
    shade: np.ndarray
    labels: np.ndarray
    interpolation: int = cv2.INTER_LINEAR
    front_to_back: bool = False

    @classmethod
    def from_boxes(
        cls,
        boxes: list[AgentBox],
        textures: list[FaceTextures],
        shade_fn,
        bake: bool = False,
        labels: np.ndarray | None = None,
    ) -> BoxSet:
        """``shade_fn(normals_world (N, 6, 3)) -> (N, 6)`` gives each face's brightness; ``bake``:
        multiply it into the textures once (static boxes) instead of per drawn face. ``labels``: (N,)
        label ids (default: each box's category, :func:`drivewm.layout.classes.label_id`)."""
        if labels is None:
            labels = np.array([label_id(b.category) for b in boxes], np.uint8)
        if not boxes:
            return cls(
                np.zeros((0, 6, 4, 3)), np.zeros((0, 6, 3)), np.zeros((0, 3)), np.zeros(0), [], np.zeros((0, 6)), labels
            )
        centers = np.array([b.center_xyz for b in boxes], np.float64)
        half = np.array([b.size_lwh for b in boxes], np.float64) / 2
        yaw = np.array([b.yaw_rad for b in boxes])
        c, s = np.cos(yaw), np.sin(yaw)
        R = np.zeros((len(boxes), 3, 3))
        R[:, 0, 0], R[:, 0, 1], R[:, 1, 0], R[:, 1, 1], R[:, 2, 2] = c, -s, s, c, 1.0
        local = _SIGNS[None] * half[:, None, None, :]  # (N, 6, 4, 3)
        corners = np.einsum("nij,nfkj->nfki", R, local) + centers[:, None, None, :]
        normals = np.einsum("nij,fj->nfi", R, _NORMALS_LOCAL)
        shade = shade_fn(normals)
        if bake:
            textures = [t.shaded(k) for t, k in zip(textures, shade)]
            shade = np.ones_like(shade)
        return cls(corners, normals, centers, np.linalg.norm(half, axis=1), textures, shade, labels)


def draw_boxes(
    img: np.ndarray,
    zbuf: np.ndarray,
    view,
    T_cam_from_world: np.ndarray,
    boxes: BoxSet,
    max_range_m: float,
    label_img: np.ndarray | None = None,
) -> None:
    """Draw every face of ``boxes`` visible to ``view`` into ``img`` (H, W, 3) uint8 with z-test
    against ``zbuf`` (H, W) float32 camera depth; ``label_img`` (H, W) uint8: also write each drawn
    pixel's box label there (the same pixels, the same z-test)."""
    if len(boxes.centers) == 0:
        return
    R, t = T_cam_from_world[:3, :3], T_cam_from_world[:3, 3]
    keep = np.flatnonzero(view.sphere_visible(boxes.centers @ R.T + t, boxes.radii, max_range_m))
    if len(keep) == 0:
        return
    quads = boxes.corners_world[keep] @ R.T + t  # (M, 6, 4, 3) camera frame
    normals = boxes.normals_world[keep] @ R.T  # (M, 6, 3)
    facing = np.einsum("mfj,mfj->mf", normals, quads[:, :, 0]) < 0  # camera on the outer side
    facing &= (quads[..., 2] >= NEAR_M).any(axis=2)
    mi, fi = np.nonzero(facing)
    if len(mi) == 0:
        return
    quads, normals = quads[mi, fi], normals[mi, fi]  # (F, 4, 3), (F, 3)
    sizes = np.array([boxes.textures[keep[m]].sizes[f] for m, f in zip(mi, fi)])  # (F, 2)
    H = _homographies(view.K, quads, sizes)
    depth_d = np.einsum("fj,fj->f", normals, quads[:, 0])
    in_front = (quads[..., 2] >= NEAR_M).all(axis=1)
    with np.errstate(divide="ignore", invalid="ignore"):
        uv_all = quads[..., :2] / quads[..., 2:3] @ view.K[:2, :2].T + view.K[:2, 2]  # (F, 4, 2)
    rects = _pixel_rects(uv_all, view.width, view.height)  # (F, 4) x0, y0, x1, y1
    near_z = np.maximum(quads[..., 2].min(axis=1), NEAR_M)  # (F,) the depth no pixel of the face is nearer than
    with np.errstate(divide="ignore", invalid="ignore"):  # rays parallel to a face plane: z = inf, never drawn
        _draw_faces(
            img, zbuf, view, boxes, keep, mi, fi, quads, normals, depth_d, H, in_front, rects, near_z, label_img
        )


def _draw_faces(
    img, zbuf, view, boxes: BoxSet, keep, mi, fi, quads, normals, depth_d, H, in_front, rects, near_z, label_img
) -> None:
    faces = np.flatnonzero(~in_front | (rects[:, 2] > rects[:, 0]) & (rects[:, 3] > rects[:, 1]))
    if boxes.front_to_back:
        faces = faces[np.argsort(near_z[faces], kind="stable")]
    for k in faces:
        box, f = keep[mi[k]], fi[k]
        if in_front[k]:
            rect = rects[k]
        else:
            uv = _project_clipped(view.K, quads[k])
            if len(uv) == 0:
                continue
            rect = _pixel_rects(uv[None], view.width, view.height)[0]
            if rect[2] <= rect[0] or rect[3] <= rect[1]:
                continue
        if near_z[k] > zbuf[rect[1] : rect[3], rect[0] : rect[2]].max() * (1 + 1e-5):
            continue  # every pixel of it lies behind what is drawn there: the z-test would refuse them all
        face = (normals[k], depth_d[k], H[k], boxes.textures[box].images[f], boxes.shade[box, f])
        draw_face(img, zbuf, view, rect, *face, label_img, int(boxes.labels[box]), boxes.interpolation)


def _pixel_rects(uv: np.ndarray, width: int, height: int) -> np.ndarray:
    """Pixel rectangles [x0, x1) x [y0, y1) (F, 4) holding polygons (F, M, 2), clipped to the image."""
    lo = np.floor(np.nan_to_num(uv.min(axis=1), nan=-1e9, posinf=1e9, neginf=-1e9).clip(-1e6, 1e6))
    hi = np.ceil(np.nan_to_num(uv.max(axis=1), nan=1e9, posinf=1e9, neginf=-1e9).clip(-1e6, 1e6)) + 1
    return np.stack(
        [lo[:, 0].clip(0, width), lo[:, 1].clip(0, height), hi[:, 0].clip(0, width), hi[:, 1].clip(0, height)], axis=1
    ).astype(int)


def _homographies(K: np.ndarray, quads: np.ndarray, sizes: np.ndarray) -> np.ndarray:
    """(F, 3, 3) maps padded texel (s, t, 1) -> image pixel: H = K [e_s, e_t, X_0 - (e_s + e_t) / 2]
    with e_s, e_t the face edges per texel and X_0 the top-left corner: inner texel (i, j) sits
    at padded (i + 1, j + 1) and its centre at X_0 + (i + 0.5) e_s + (j + 0.5) e_t."""
    e_s = (quads[:, 1] - quads[:, 0]) / sizes[:, :1]
    e_t = (quads[:, 3] - quads[:, 0]) / sizes[:, 1:]
    cols = np.stack([e_s, e_t, quads[:, 0] - 0.5 * (e_s + e_t)], axis=2)  # (F, 3, 3)
    return K @ cols


def clip_near(poly_cam: np.ndarray, near: float = NEAR_M) -> np.ndarray:
    """Sutherland-Hodgman clip of a convex polygon (M, 3) to z >= near."""
    out = []
    for a, b in zip(poly_cam, np.roll(poly_cam, -1, axis=0)):
        if a[2] >= near:
            out.append(a)
        if (a[2] >= near) != (b[2] >= near):
            out.append(a + (near - a[2]) / (b[2] - a[2]) * (b - a))
    return np.array(out) if len(out) >= 3 else np.zeros((0, 3))


def _project_clipped(K: np.ndarray, quad_cam: np.ndarray) -> np.ndarray:
    poly = clip_near(quad_cam)
    if len(poly) == 0:
        return np.zeros((0, 2))
    return poly[:, :2] / poly[:, 2:3] @ K[:2, :2].T + K[:2, 2]


def draw_face(
    img: np.ndarray,
    zbuf: np.ndarray,
    view,
    rect: np.ndarray,
    normal_cam: np.ndarray,
    plane_d: float,
    H: np.ndarray,
    tex_rgba: np.ndarray,
    shade: float,
    label_img: np.ndarray | None = None,
    label: int = 0,
    interpolation: int = cv2.INTER_LINEAR,
) -> None:
    """Fill one planar face inside the pixel rectangle ``rect`` (x0, y0, x1, y1) where it is nearer
    than the z-buffer: plane n . X = d in the camera frame, padded-texel -> pixel homography ``H``;
    and, given ``label_img``, write ``label`` at the same pixels."""
    x0, y0, x1, y1 = rect
    M = H.copy()
    M[0] -= x0 * H[2]
    M[1] -= y0 * H[2]
    warped = cv2.warpPerspective(
        tex_rgba, M, (int(x1 - x0), int(y1 - y0)), flags=interpolation, borderMode=cv2.BORDER_CONSTANT
    )
    nx, ny, nz = (float(v) for v in normal_cam)  # Python floats keep the per-pixel maths in float32
    z = float(plane_d) / (nx * view.xn[None, x0:x1] + ny * view.yn[y0:y1, None] + nz)
    zroi = zbuf[y0:y1, x0:x1]
    win = (warped[..., 3] > 127) & (z < zroi) & (z > 0)
    if not win.any():
        return
    rgb = warped[..., :3]
    if shade != 1.0:
        rgb = cv2.convertScaleAbs(rgb, alpha=float(shade))
    mask = win.view(np.uint8)
    cv2.copyTo(rgb, mask, img[y0:y1, x0:x1])  # writes into the views in place (10-30x np.copyto with where)
    cv2.copyTo(z, mask, zroi)
    if label_img is not None:
        label_img[y0:y1, x0:x1][win] = label
