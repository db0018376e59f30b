"""Lighting computed at the vertices on the CPU (Gouraud shading), for software OpenGL.

Under Mesa's llvmpipe (Xvfb, VMs, laptops without a working GPU driver) every
lit pixel runs VTK's per-fragment lighting in software: measured on the app's
four views, lighting took a third of each frame's render, and most of it went
to the large translucent jaw and palate.  A surface whose colours already hold
the light needs none of that: its actor is drawn unlit and only interpolates
the colours between the vertices.  The nodes are 2-3 mm apart on a 5 cm tongue,
so Gouraud shading from smooth vertex normals reads as a smooth surface (VTK's
default for these actors was flat shading, faceted, from screen-space
derivatives).

:func:`shade` is VTK's lighting model for the app's lights (camera lights:
each view's lights follow its camera), evaluated per vertex:

    colour = ambient · base + diffuse · base · Σ_l I_l max(0, n·L_l)
             + specular · Σ_l I_l max(0, r_l·v)^p      (r_l: L_l reflected about n)

in view coordinates (x right, y up, z towards the viewer).  A closed surface
(the tongue, the jaw and palate shells) is seen from outside only: its outward
normals are used as they are.  An open sheet (a traced palate) is lit on the
side the viewer sees (``two_sided``: a normal facing away from the viewer is
flipped, as VTK flips a back face's).  No Qt, no VTK import: NumPy only.
"""

from __future__ import annotations

import numpy as np

#: (direction the light comes *from*, in camera coordinates: x right, y up, z towards the
#: viewer; intensity).  None: a headlight, from the camera itself.
Light = tuple


def light_vectors(lights) -> tuple[np.ndarray, np.ndarray]:
    """(k, 3) unit vectors towards each light in view coordinates and (k,) intensities.

    ``lights``: ((direction or None, intensity), ...) as :data:`tonguevis.render.scene.LIGHTS`,
    where a direction is the light's position relative to the focal point in VTK's
    camera-light frame (the camera at +z looking at the origin, y up) and None is a headlight.
    """
    towards, intensity = [], []
    for direction, strength in lights:
        d = np.array((0.0, 0.0, 1.0) if direction is None else direction, dtype=np.float64)
        towards.append(d / np.linalg.norm(d))
        intensity.append(float(strength))
    return np.array(towards).reshape(-1, 3), np.array(intensity)


def shade(base: np.ndarray, normals: np.ndarray, points: np.ndarray, view: np.ndarray,
          lights, ambient: float = 0.0, diffuse: float = 1.0, specular: float = 0.0,
          specular_power: float = 1.0, parallel=False, two_sided: bool = False) -> np.ndarray:
    """Lit colours of a surface's vertices, as VTK would light them at those vertices.

    base : (n, 3) or (3,) colours in [0, 1] (the colour-mapped scalars or the actor's colour);
    normals : (n, 3) unit vertex normals and points : (n, 3) positions, world coordinates (m);
    view : (4, 4) the camera's world-to-view matrix (VTK's ``GetViewTransformMatrix``), or
    (v, 4, 4) the matrices of v views lit at once (one pass over the arrays for all of them);
    lights : as :func:`light_vectors`; ambient, diffuse, specular, specular_power : the
    actor's material; parallel : an orthographic camera (the view direction is then +z),
    one bool or one per view; two_sided : light the side facing the viewer (open sheets; see
    the module's docstring).
    Returns (n, 3) uint8 RGB, or (v, n, 3) for a stack of views.
    """
    view = np.asarray(view, dtype=np.float64)
    stacked = view.ndim == 3
    views = view if stacked else view[None]
    v = len(views)
    rotation = views[:, :3, :3]  # (v, 3, 3)
    n = np.asarray(normals, dtype=np.float64)[None] @ rotation.transpose(0, 2, 1)  # (v, n, 3)
    parallel = np.broadcast_to(np.asarray(parallel, dtype=bool), (v,))
    # Towards the eye: +z for an orthographic view, from the vertex to the camera otherwise.
    to_eye = np.zeros(n.shape)
    to_eye[..., 2] = 1.0
    perspective = np.flatnonzero(~parallel)
    if len(perspective):
        position = np.asarray(points, dtype=np.float64)[None] @ rotation[perspective].transpose(0, 2, 1) \
            + views[perspective, None, :3, 3]
        to_eye[perspective] = -position / np.maximum(np.linalg.norm(position, axis=-1, keepdims=True), 1e-12)
    facing = np.einsum("vij,vij->vi", n, to_eye)
    if two_sided:
        flip = facing < 0.0
        n[flip] = -n[flip]
        facing = np.abs(facing)
    towards, intensity = light_vectors(lights)
    cosines = n @ towards.T  # (v, n, k)
    lit = np.maximum(cosines, 0.0) @ intensity
    colour = (ambient + diffuse * lit)[..., None] * np.asarray(base, dtype=np.float64)
    if specular > 0.0:
        # r·v with r the light's direction of travel (-towards) reflected about n:
        # r = 2 (n·l) n - l, so r·v = 2 (n·l)(n·v) - l·v.
        along = np.maximum(2.0 * cosines * facing[..., None] - to_eye @ towards.T, 0.0)
        highlight = np.where(cosines > 0.0, along ** specular_power, 0.0) @ intensity
        colour = colour + specular * highlight[..., None]
    rgb = np.clip(np.rint(255.0 * colour), 0, 255).astype(np.uint8)
    return rgb if stacked else rgb[0]
