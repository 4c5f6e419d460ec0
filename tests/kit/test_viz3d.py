"""The notebooks' 3D scene view: frustum geometry, and both renderers run."""
import matplotlib
import numpy as np
import pytest

from graders.kit import scene
from graders.kit.viz3d import frustum_wireframe, show_scene

matplotlib.use("Agg")


def test_frustum_apex_is_the_centre_and_the_image_plane_is_in_front():
    rng = np.random.default_rng(0)
    R, C = scene.random_rotation(rng), rng.normal(0, 5, 3)
    t = -R @ C
    W = frustum_wireframe(R, t, size=0.5)
    strokes = np.split(W, np.flatnonzero(np.isnan(W[:, 0])) + 1)
    assert np.allclose(strokes[0][0], C)                               # first stroke starts at the centre
    pts = W[~np.isnan(W[:, 0])]
    depth = (pts - C) @ R[2]                                           # along the optical axis
    assert np.all((np.isclose(depth, 0) & np.isclose(np.linalg.norm(pts - C, axis=1), 0)) | np.isclose(depth, 0.5))
    top = strokes[5][1]                                                # the "up" marker lies towards −y
    assert (top - C) @ R[1] < 0


@pytest.mark.parametrize("static", [True, False])
def test_show_scene_draws(static, monkeypatch):
    shown = []
    if static:
        import matplotlib.pyplot as plt
        monkeypatch.setattr(plt, "show", lambda: shown.append(plt.gcf()))
    else:
        import plotly.graph_objects as go
        monkeypatch.setattr(go.Figure, "show", lambda self, *a, **k: shown.append(self))
    rng = np.random.default_rng(1)
    cams = [(scene.random_rotation(rng), rng.normal(size=3)) for _ in range(3)]
    show_scene(rng.normal(size=(40, 3)), cams, ghost_points=rng.normal(size=(10, 3)), ghost_cameras=cams[:1],
               static=static)
    assert len(shown) == 1
    if not static:
        names = [tr.name for tr in shown[0].data]
        assert names == ["ground truth", "true cameras", "points", "cameras", "order"]
        assert len(shown[0].data[2].x) == 40
