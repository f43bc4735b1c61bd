"""Scene estimation: 3D fruit from tracks and depth, the persistent fruit list, the trunk and the
obstacle set (paper §III-A to §III-C, §IV-B); answers every perception/tracks with scene/state."""

from typing import Literal

from pydantic import Field, model_validator
from pydantic_settings import SettingsConfigDict

from services.runtime import NodeSpec, ServiceDef, ServiceSettings

HsvTriple = tuple[int, int, int]
NEAR_RADIUS_MIN_M = 0.002  # the controller refuses spheres under 1 mm


class Settings(ServiceSettings):
    """Settings of the scene estimator."""

    model_config = SettingsConfigDict(env_prefix="HARVEST_SCENE_")

    # ---- inputs ------------------------------------------------------------------------------
    frame_buffer: int = Field(
        default=8, ge=1, le=256, description="Camera frames kept to join tracks to their frame."
    )
    accept_tentative: bool = Field(
        default=False,
        description="Let tracks not yet confirmed by the tracker enter the fruit list (false: "
        "only confirmed tracks, as Deep SORT reports them).",
    )
    # ---- fruit in 3D (paper §III-A) ----------------------------------------------------------
    fruit_method: Literal["surface", "paper"] = Field(
        default="surface",
        description="'surface': box tangent planes + every depth pixel of the visible surface; "
        "'paper': eq. (2)-(4) with the median depth of a small window at the box centre.",
    )
    paper_window_px: int = Field(
        default=5, ge=1, le=51, description="'paper': side of the centre depth window, px."
    )
    central_fraction: float = Field(
        default=0.7,
        gt=0.1,
        le=1.0,
        description="Depth pixels used: inside this share of the fruit ellipse's semi-axes.",
    )
    min_depth_pixels: int = Field(
        default=8, ge=1, description="Fewest valid depth pixels for an estimate."
    )
    min_support_share: float = Field(
        default=0.05,
        gt=0,
        le=1,
        description="Share of a box's depth pixels that the fruit's surface must hold (the "
        "farthest such surface is the fruit: occluders are nearer).",
    )
    occluder_margin_m: float = Field(
        default=0.01,
        ge=0,
        le=0.2,
        description="A box side is cut by an occluder when what lies beyond it is nearer than "
        "the fruit's silhouette by more than this (plus a quarter of the fruit's size), m.",
    )
    edge_strip_px: int = Field(
        default=3, ge=1, le=20, description="Width of the strip tested beyond a box side, px."
    )
    border_margin_px: float = Field(
        default=1.0, ge=0, le=20, description="A box side this near the image border is cut, px."
    )
    min_semi_axis_m: float = Field(
        default=0.025,
        gt=0,
        description="Smallest plausible fruit semi-axis d_h, m (oranges: 3-5 cm radius). A "
        "smaller estimate is a partial view (a fruit mostly hidden, a box on a part of it): "
        "refused, the fruit keeps its state.",
    )
    max_semi_axis_m: float = Field(
        default=0.12, gt=0, description="Largest plausible fruit semi-axis d_h, m."
    )
    v_over_h_prior: float = Field(
        default=1.0,
        ge=0.5,
        le=2.0,
        description="d_v/d_h assumed for a fruit with a cut box side until it or "
        "v_over_h_population_min_fruit other fruit were seen whole.",
    )
    v_over_h_population_min_fruit: int = Field(
        default=3,
        ge=0,
        le=100,
        description="A fruit with a cut box side never seen whole takes the median d_v/d_h of "
        "the fruit seen whole in the list once there are at least this many (0: the prior).",
    )
    misfit_tie_shape_tolerance: float = Field(
        default=0.04,
        ge=0,
        le=1,
        description="When two fits of a box (a side cut or not) contradict the image equally, "
        "the one whose d_v/d_h is further than this share from the fruit's measured ratio "
        "loses (0: off; the fewest cut sides win ties).",
    )
    corner_fit: bool = Field(
        default=False,
        description="A box cut on a horizontal and a vertical side (a fruit hidden at a "
        "corner): try sizes from the smallest that spans the box to 1.6 times it, tangent to "
        "the two whole sides, and keep the one the image contradicts least (false: the box is "
        "taken as the silhouette).",
    )
    fruit_hsv_low: HsvTriple = Field(
        default=(0, 140, 50), description="Fruit colour, OpenCV HSV lower bound (inclusive)."
    )
    fruit_hsv_high: HsvTriple = Field(
        default=(30, 255, 255), description="Fruit colour, OpenCV HSV upper bound (inclusive)."
    )
    refine_box: bool = Field(
        default=True,
        description="Shrink each track's box to the fruit-coloured pixels at the fruit's depth "
        "inside it before measuring (a detector's boxes are a few pixels loose).",
    )
    refine_keeps_holes: bool = Field(
        default=True,
        description="The refined box keeps the box's fruit-coloured pixels that have no depth "
        "(the stereo shadow of a nearer object); false: only pixels with depth count.",
    )
    min_colour_share: float = Field(
        default=0.15,
        ge=0,
        le=1,
        description="Fewest fruit-coloured pixels, as a share of the box's valid depth pixels, "
        "for an estimate: a detection on a hand, a branch or a leaf is not a fruit.",
    )
    # ---- the robot self-filter ---------------------------------------------------------------
    robot_self_filter: bool = Field(
        default=True,
        description="Drop a fruit estimate that lies inside the robot's own arms or tools (the "
        "LWR's orange links look like oranges): capsules at the last joint state before the "
        "frame's stamp. Once a joint state has been received, a Tracks message waits for it.",
    )
    joint_state_max_lag_ms: float = Field(
        default=10.0,
        gt=0,
        le=1000,
        description="The self-filter uses the last joint state before the frame's stamp, at most "
        "this much older (the sim's control period is 8.3 ms), ms.",
    )
    self_filter_share: float = Field(
        default=0.5,
        ge=0,
        le=2,
        description="An estimate whose centre is closer to a link's axis than the link radius "
        "plus this share of its d_h is the robot itself (a real fruit touching the link is a "
        "whole d_h out).",
    )
    prefer_whole_views: bool = Field(
        default=False,
        description="A fruit whose stored state comes from a whole view (no side cut) keeps it "
        "against views with a side cut by an occluder or the border. Off by default: it held a "
        "fruit moved by a hand at its old place for seconds (paper-exp1 centre p95 2 → 67 mm); "
        "the planner keeps its target from a whole view instead.",
    )
    # ---- the persistent list (paper §III-B) --------------------------------------------------
    update_threshold_m: float = Field(
        default=0.04,
        gt=0,
        description="A new position farther than this from the stored one is not taken (the "
        "paper's guard against temporary ID errors), m.",
    )
    forget_after_frames: int = Field(
        default=100, ge=1, description="Fruit IDs unseen for this many frames are forgotten."
    )
    accept_jump_frames: int = Field(
        default=15,
        ge=0,
        description="A position jump confirmed by this many consecutive frames is taken (the "
        "fruit really moved); 0 never takes one (the paper's rule).",
    )
    unmark_moved_harvested: bool = Field(
        default=False,
        description="Opt-in: a harvested fruit's ID whose jump the list takes, to a place "
        "outside our dish, is on another fruit: its harvested mark is dropped, so that fruit is "
        "an obstacle again (orchard seed 10). Off by default: measured, the planner's book then "
        "keeps the ID on a record that follows another fruit, and the run lost a fruit "
        "(BENCHMARKS, Harvest, session 36).",
    )
    # ---- the trunk (paper §III-C) ------------------------------------------------------------
    trunk_method: Literal["circle", "paper"] = Field(
        default="circle",
        description="'circle': camera-facing circle fit of the mask's 3D points; 'paper': the "
        "mean pixel and mean depth of the mask (a point on the trunk's front surface).",
    )
    trunk_max_depth_m: float = Field(
        default=2.0, gt=0, le=20, description="Depth mask: farthest trunk pixel kept, m."
    )
    trunk_hsv_low: HsvTriple = Field(
        default=(10, 70, 80), description="Trunk colour, OpenCV HSV lower bound (the paper's)."
    )
    trunk_hsv_high: HsvTriple = Field(
        default=(20, 130, 140), description="Trunk colour, OpenCV HSV upper bound (the paper's)."
    )
    trunk_min_pixels: int = Field(default=50, ge=1, description="Fewest mask pixels for a fix.")
    trunk_min_radius_m: float = Field(
        default=0.03,
        gt=0,
        description="Smallest trunk radius, m (6 cm across: thinner is a branch, which also "
        "passes the colour mask).",
    )
    trunk_max_radius_m: float = Field(default=0.2, gt=0, description="Largest trunk radius, m.")
    trunk_min_height_m: float = Field(
        default=0.4,
        gt=0,
        description="Height of trunk a fix must see, m: a trunk runs from the ground into the "
        "crown, a near-vertical branch piece is shorter.",
    )
    trunk_smoothing: float = Field(
        default=0.2, gt=0, le=1, description="Gain of the exponential average over frames."
    )
    trunk_gate_m: float = Field(
        default=0.1, gt=0, description="Fixes farther than this from the estimate are outliers, m."
    )
    trunk_reacquire_frames: int = Field(
        default=5, ge=1, description="Consecutive agreeing outliers that replace the estimate."
    )
    trunk_forget_after_frames: int = Field(
        default=100, ge=1, description="Frames without a fix after which the trunk is not found."
    )
    trunk_tool_margin_m: float = Field(
        default=0.08,
        ge=0,
        le=1,
        description="The trunk obstacle's surface passes this far behind the selected fruit's "
        "back (the paper: 0): the collecting dish, centred under the fruit, reaches 4.5 cm past "
        "it and the damper keeps d_s more, m.",
    )
    trunk_default_radius_m: float = Field(
        default=0.08,
        gt=0,
        description="Trunk radius when none is measured ('paper' method): the obstacle's "
        "smallest radius, m.",
    )
    # ---- occupied space from depth (branches) -------------------------------------------
    occupancy: bool = Field(
        default=True,
        description="Publish bark-coloured depth points (branches) as sphere obstacles, kept "
        "in a persistent world voxel grid (services/scene/occupancy.py).",
    )
    occupancy_voxel_m: float = Field(default=0.04, gt=0.005, le=0.5, description="Voxel side, m.")
    occupancy_sphere_radius_m: float = Field(
        default=0.03,
        gt=0,
        le=0.5,
        description="Radius of each voxel's sphere, centred on the mean of its points (covers "
        "the voxel's points and the branch's unseen back), m.",
    )
    occupancy_stride_px: int = Field(
        default=3, ge=1, le=32, description="Every this-many-th pixel in u and v is used."
    )
    occupancy_max_depth_m: float = Field(
        default=1.6, gt=0, le=20, description="Farthest depth used, m (beyond: background)."
    )
    occupancy_min_points: int = Field(
        default=3, ge=1, description="Fewest of a frame's points for a voxel to count as hit."
    )
    occupancy_robot_margin_m: float = Field(
        default=0.04,
        ge=0,
        le=0.5,
        description="Points within a robot capsule's radius plus this are the robot, m.",
    )
    occupancy_clear_frames: int = Field(
        default=3,
        ge=1,
        description="Consecutive frames seeing valid depth behind a voxel that forget it.",
    )
    occupancy_clear_margin_m: float = Field(
        default=0.06,
        gt=0,
        description="Depth behind a voxel's centre by more than this counts as free space, m.",
    )
    occupancy_forget_after_frames: int = Field(
        default=900,
        ge=1,
        description="A voxel not hit for this many frames is forgotten (15 Hz: 60 s); hidden "
        "voxels (behind an arm) are kept until then.",
    )
    occupancy_history_frames: int = Field(
        default=15,
        ge=0,
        description="A voxel born where one of this many recent frames saw depth behind it is a "
        "newcomer: something moved into free space (a hand). 0: none is.",
    )
    occupancy_history_every_frames: int = Field(
        default=15,
        ge=1,
        description="… or where one of the frames kept one in this many (15 Hz: one a second) saw "
        "depth behind it (the recent frames may not: the arms, or the hand itself, in front).",
    )
    occupancy_history_long_frames: int = Field(
        default=60,
        ge=0,
        description="… of which the last this many are kept (a minute). 0: only the recent ones.",
    )
    occupancy_transient_forget_frames: int = Field(
        default=5,
        ge=1,
        description="A newcomer is forgotten this many frames after its last hit, hidden or not.",
    )
    occupancy_settle_hits: int = Field(
        default=45,
        ge=1,
        description="… unless it was hit in this many frames (it stayed): then it is kept like "
        "a branch seen from the start.",
    )
    occupancy_blank_frames: int = Field(
        default=15,
        ge=0,
        description="A voxel whose pixel shows no depth return and no bark for this many frames "
        "since its last hit, the robot not in its line of sight, is forgotten: nothing stands "
        "there and nothing behind it is in range (a hand swept in front of the sky). 0: never.",
    )
    occupancy_max_obstacles: int = Field(
        default=200,
        ge=0,
        le=450,
        description="At most this many spheres (the most recently hit): the controller refuses "
        "scenes over its max_obstacles (500) with the fruit and the trunk.",
    )
    contact_obstacles: bool = Field(
        default=True,
        description="Keep what the arms felt (the joint states' contacts, outside the selected "
        "fruit's inner working space) as sphere obstacles 'touched_…' beside the branches', "
        "split by the same keep-out; forgotten where a fruit is harvested; a place on a fruit's "
        "estimated skin or felt only on its own attempts is part of it (own_fruit_ids, "
        "touched.py). On the orchard's 20 seeds: 85 of 101 reachable fruit against 82, 131 "
        "collisions against 173 (session 42, both ways on one VM).",
    )
    contact_voxel_m: float = Field(
        default=0.03, gt=0.005, le=0.2, description="… felt points are binned at this size, m."
    )
    contact_sphere_radius_m: float = Field(
        default=0.035,
        ge=0.002,
        le=0.1,
        description="… a felt voxel's sphere radius (0.02 on seeds 8, 9, 12: the dampers pushed "
        "the dish off one new sphere after another, 42 contacts with one branch), m.",
    )
    occupancy_unseen_fruit: bool = Field(
        default=False,
        description="Also keep fruit-coloured depth points that no fruit estimate explains (a "
        "fruit behind leaves the detector misses: orchard seed 18's collecting arm touched two "
        "such, 6-13 % visible, 35 times) in a second voxel grid with the same settings, "
        "published as sphere obstacles 'unseen_fruit_…' beside the branches'. Points within "
        "a fruit estimate's largest semi-axis plus occupancy_unseen_fruit_margin_m of its centre "
        "(harvested ones aside: the dish's own sphere filters those) are that fruit's.",
    )
    occupancy_unseen_fruit_margin_m: float = Field(
        default=0.03,
        ge=0,
        le=0.2,
        description="See occupancy_unseen_fruit: an estimate explains the fruit-coloured points "
        "within its largest semi-axis plus this of its centre (the estimates of partly hidden "
        "fruit are a few cm off), m.",
    )
    occupancy_unseen_fruit_max_obstacles: int = Field(
        default=60,
        ge=0,
        le=200,
        description="At most this many unseen-fruit spheres (the most recently hit); with "
        "occupancy_max_obstacles and the fruit they stay under the controller's 500.",
    )
    occupancy_target_clearance_m: float = Field(
        default=0.2,
        ge=0,
        le=1,
        description="No sphere comes within d_v plus this of the selected fruit's centre: the "
        "dish must get under it and the cutter to its peduncle, next to its own branch's tip, m.",
    )
    occupancy_target_corridor_m: float = Field(
        default=0.0,
        ge=0,
        le=1,
        description="The keep-out reaches this far from the selected fruit's centre towards the "
        "camera along its optical axis (the tools' approach line: the pre-pose is d_z in front), "
        "as a capsule of the same radius: no sphere within d_v + occupancy_target_clearance_m of "
        "that segment. 0: a sphere round the fruit only, m.",
    )
    occupancy_near_radius_m: float = Field(
        default=0.01,
        ge=0,
        le=0.1,
        description="0: the spheres inside the keep-out are left out of the obstacles. Above 0 "
        "(at least 2 mm): those outside the inner working space are passed on at this radius "
        "(the points' mean, not inflated to the voxel), so the dampers hold the arms off the "
        "branches seen near the target by their own distance only, m.",
    )
    occupancy_near_hold_m: float = Field(
        default=0.01,
        ge=0,
        le=0.05,
        description="With occupancy_near_radius_m: a sphere shown to the controller in the last "
        "state for the same selected fruit stays shown until it lies this much inside the inner "
        "working space (the fruit's estimate moves a few mm from view to view, and with it the "
        "space's edge: orchard seed 19, a branch the dish felt at that edge was shown and hidden "
        "on alternate states and the dish struck it 12 times in 2 s, twice with the hold; "
        "orchard, 20 seeds: 108 collisions against 116, BENCHMARKS.md, Harvest, session 49), "
        "m. 0: no hold.",
    )
    occupancy_inner_clearance_m: float = Field(
        default=0.05,
        ge=0,
        le=1,
        description="With occupancy_near_radius_m: no sphere at all within d_v plus this of the "
        "selected fruit's centre, nor of the segment up from it to d_v plus "
        "occupancy_inner_twig_m above it (the fruit's own twig, where the cutter closes), m.",
    )
    occupancy_inner_twig_m: float = Field(
        default=0.10, ge=0, le=0.5, description="See occupancy_inner_clearance_m, m."
    )

    @model_validator(mode="after")
    def _near_radius(self) -> "Settings":
        if 0 < self.occupancy_near_radius_m < NEAR_RADIUS_MIN_M:
            raise ValueError(
                f"occupancy_near_radius_m {self.occupancy_near_radius_m} is below "
                f"{NEAR_RADIUS_MIN_M} m (the controller refuses smaller spheres); 0 turns it off"
            )
        return self


SPEC = NodeSpec(
    inputs=("camera/rgbd", "robot/joint_state", "perception/tracks", "harvest/events"),
    outputs=("scene/state",),
    answers={"perception/tracks": ("scene/state",)},
)


def _make_core(settings: Settings):
    from services.scene.core import SceneCore

    return SceneCore(settings)


SERVICE = ServiceDef(
    "scene", Settings, SPEC, kind="reactive", make_core=_make_core, description=__doc__ or ""
)
