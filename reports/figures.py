"""Plotly figures of the reports: the scene with camera frusta, PSNR vs number of views, grid curves with bands."""
from __future__ import annotations

from collections import defaultdict

import numpy as np
import plotly.graph_objects as go

from reports import colors
from reports.cameras import CameraView, frustum_depth, frustum_segments

CAMERA_META = "cameras"  # `meta` of the marker traces that hold one marker per camera (the browser tests count them)
PLOT_CONFIG = {"displaylogo": False, "responsive": True}


def _hover(cam: CameraView) -> str:
    lines = [f"<b>{cam.name}</b>", cam.group] + [f"{k}: {v}" for k, v in cam.info.items()]
    if cam.gain is not None:
        lines.append(f"gain: {cam.gain:.4g}")
    return "<br>".join(lines)


def scene_figure(points: np.ndarray, point_colors: np.ndarray, cams: list[CameraView], title: str = "",
                 height: int = 620) -> go.Figure:
    """Gaussian centres [M, 3] in their colours [M, 3] uint8 and one frustum per camera.

    Per camera group (in order of first appearance): a line trace of the frusta and a marker trace (meta
    `CAMERA_META`, one marker per camera at its centre, text = its label). Cameras that carry a gain and
    belong to a group without a fixed colour meaning ("candidates...") are coloured by gain on `colors.GAIN_SCALE`.
    """
    fig = go.Figure()
    if len(points):
        fig.add_trace(go.Scatter3d(
            x=points[:, 0], y=points[:, 1], z=points[:, 2], mode="markers", name="Gaussians", hoverinfo="skip",
            marker={"size": 1.6, "color": [f"rgb({r},{g},{b})" for r, g, b in point_colors.tolist()]}))
    center = np.median(points, axis=0) if len(points) else (
        np.mean([c.position for c in cams], axis=0) if cams else np.zeros(3))
    depth = frustum_depth(cams, center)
    groups: dict[str, list[CameraView]] = defaultdict(list)
    for cam in cams:
        groups[cam.group].append(cam)
    gains = [c.gain for c in cams if c.gain is not None and c.group.startswith("candidates")]
    gain_range = (min(gains), max(gains)) if gains else None
    for group, members in groups.items():
        seg = frustum_segments(members, depth)
        if len(seg):
            fig.add_trace(go.Scatter3d(x=seg[:, 0], y=seg[:, 1], z=seg[:, 2], mode="lines", legendgroup=group,
                                       showlegend=False, hoverinfo="skip",
                                       line={"color": members[0].color, "width": 2}))
        pos = np.stack([c.position for c in members])
        labels = [c.label for c in members]
        marker: dict = {"size": 4, "color": members[0].color}
        by_gain = gain_range is not None and group.startswith("candidates") and all(c.gain is not None
                                                                                     for c in members)
        if by_gain:
            marker = {"size": 5, "color": [c.gain for c in members], "colorscale": colors.GAIN_SCALE,
                      "cmin": gain_range[0], "cmax": gain_range[1],
                      "colorbar": {"title": {"text": "gain"}, "len": 0.5, "x": 1.0}}
        fig.add_trace(go.Scatter3d(
            x=pos[:, 0].tolist(), y=pos[:, 1].tolist(), z=pos[:, 2].tolist(), mode="markers+text" if any(labels) else "markers",
            text=labels, textposition="top center", textfont={"size": 11, "color": members[0].color},
            name=f"{group} ({len(members)})", legendgroup=group, meta=CAMERA_META, marker=marker,
            hovertext=[_hover(c) for c in members], hoverinfo="text"))
    fig.update_layout(title=title or None, height=height, margin={"l": 0, "r": 0, "t": 30 if title else 0, "b": 0},
                      legend={"itemsizing": "constant", "x": 0.0, "y": 1.0, "bgcolor": "rgba(255,255,255,0.6)"},
                      scene={"aspectmode": "data", "xaxis": {"visible": False}, "yaxis": {"visible": False},
                             "zaxis": {"visible": False}, "camera": view_from(cams)})
    return fig


def view_from(cams: list[CameraView]) -> dict:
    """A plotly scene camera with the cameras' mean up direction (OpenCV y is down) as up, seen from the side
    and 35 degrees above."""
    ups = [-c.rotation[:, 1] for c in cams if c.rotation is not None]
    up = np.mean(ups, axis=0) if ups else np.array([0.0, 0.0, 1.0])
    up = up / np.linalg.norm(up) if np.linalg.norm(up) > 1e-9 else np.array([0.0, 0.0, 1.0])
    side = np.cross(up, [1.0, 0.0, 0.0] if abs(up[0]) < 0.9 else [0.0, 1.0, 0.0])
    side = side / np.linalg.norm(side)
    eye = 1.5 * (np.cos(np.radians(35)) * side + np.sin(np.radians(35)) * up)
    return {"up": dict(zip("xyz", up.tolist())), "eye": dict(zip("xyz", eye.tolist()))}


def psnr_views_figure(curve: list[tuple[int, float, str]], height: int = 340) -> go.Figure:
    """Test PSNR against the number of training views (one marker per stage and the final value)."""
    fig = go.Figure(go.Scatter(x=[c[0] for c in curve], y=[c[1] for c in curve], mode="lines+markers",
                               hovertext=[f"{c[2]}: {c[1]:.2f} dB at {c[0]} views" for c in curve],
                               hoverinfo="text", name="test PSNR"))
    fig.update_layout(height=height, margin={"l": 50, "r": 10, "t": 10, "b": 40},
                      xaxis_title="training views", yaxis_title="test PSNR (dB)")
    return fig


def band_figure(series: dict[str, tuple[np.ndarray, np.ndarray, np.ndarray, int]], title: str,
                height: int = 360) -> go.Figure:
    """Mean +- std bands: {method: (views [S], mean [S], std [S], number of seeds)}, one colour per method."""
    fig = go.Figure()
    for i, (method, (x, mean, std, seeds)) in enumerate(series.items()):
        color = colors.STAGES[i % len(colors.STAGES)]
        r, g, b = colors.hex_to_rgb(color)
        if seeds > 1:
            fig.add_trace(go.Scatter(x=np.concatenate([x, x[::-1]]), y=np.concatenate([mean + std, (mean - std)[::-1]]),
                                     fill="toself", fillcolor=f"rgba({r},{g},{b},0.18)", line={"width": 0},
                                     hoverinfo="skip", showlegend=False, legendgroup=method))
        fig.add_trace(go.Scatter(x=x, y=mean, mode="lines+markers", name=f"{method} ({seeds} seed{'s' * (seeds > 1)})",
                                 line={"color": color}, legendgroup=method,
                                 hovertext=[f"{method}: {m:.2f} ± {s:.2f} dB at {v} views"
                                            for v, m, s in zip(x, mean, std)], hoverinfo="text"))
    fig.update_layout(title=title, height=height, margin={"l": 50, "r": 10, "t": 40, "b": 40},
                      xaxis_title="training views", yaxis_title="test PSNR (dB), mean ± std over seeds")
    return fig
