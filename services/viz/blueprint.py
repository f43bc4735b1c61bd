"""The default layout: 3D scene and event log on the left; camera, depth and plots on the right."""

from __future__ import annotations

from typing import Any

from services.viz import paths


def blueprint() -> Any:
    """A ``rerun.blueprint.Blueprint`` (built on call: rerun is imported lazily)."""
    import rerun.blueprint as rrb

    camera = rrb.Spatial2DView(
        name="camera",
        origin=paths.IMAGE,
        contents=["$origin/**", f"- {paths.DEPTH}"],
    )
    depth = rrb.Spatial2DView(
        name="depth",
        origin=paths.IMAGE,
        contents=[paths.DEPTH, paths.TRACKS],
    )
    plots = rrb.Tabs(
        rrb.TimeSeriesView(name="task errors", origin=paths.ERRORS),
        rrb.TimeSeriesView(name="min distance vs d_s", origin=paths.DISTANCES),
        rrb.TimeSeriesView(name="joint velocity / limit", origin=paths.JOINT_VELOCITY),
        rrb.TimeSeriesView(name="solve time", origin=paths.SOLVE_TIME),
        rrb.TimeSeriesView(name="dampers", origin=paths.DAMPERS),
        rrb.TimeSeriesView(name="demo", origin=f"{paths.PLOTS}/demo"),
    )
    return rrb.Blueprint(
        rrb.Horizontal(
            rrb.Vertical(
                rrb.Spatial3DView(
                    name="scene",
                    origin="/",
                    # the depth cloud hides the fruit it surrounds: one click adds it back
                    contents=[
                        f"{paths.WORLD}/**",
                        f"{paths.ROBOT}/**",
                        f"- {paths.DEPTH}",
                        f"- {paths.TRUNK_MASK}",
                    ],
                    # behind and above the robot, looking at the tree in front of it
                    eye_controls=rrb.EyeControls3D(
                        position=(-1.5, -2.1, 2.5), look_target=(0.9, 0.0, 1.1), eye_up=(0, 0, 1)
                    ),
                ),
                rrb.TextLogView(name="events", origin=paths.LOG),
                row_shares=[3, 1],
            ),
            rrb.Vertical(rrb.Tabs(camera, depth), plots, row_shares=[1, 1]),
            column_shares=[3, 2],
        ),
        rrb.TimePanel(timeline=paths.SIM_TIME, state="collapsed"),
        collapse_panels=True,
    )
