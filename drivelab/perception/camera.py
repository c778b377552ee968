"""First-person pinhole camera on the ego, drawn with OpenCV from the WorldState (the CARLA study):
sky, grass, the road, white lane markings, the yellow guide line of follow-line circuits, other
vehicles as shaded 3-D boxes and traffic lights, through ``pinhole.PinholeModel``. The same
projection draws ground-truth masks of the ego lane's lines and of the guide line. Ground shapes
are culled, clipped, projected and filled with ``cv2.LINE_8``, so that a marking and its mask
cover exactly the same pixels.
"""

from __future__ import annotations

import cv2
import numpy as np
from gymnasium import spaces

from drivelab.perception.base import ZEBRA_STRIPE_M, Sensor, box_corners, ego_frame
from drivelab.perception.birdeye import DashedMarkings, solid_markings, zebra_boxes
from drivelab.perception.topdown import SHIFT, LanePolygons, _clip_half_plane, fixed_point, segments_near
from drivelab.world.batch import WorldBatch
from drivelab.world.pinhole import PinholeModel
from drivelab.world.road_geometry import GuideSegments, polyline_segments
from drivelab.world.state import LIGHT_GREEN, LIGHT_RED, LIGHT_YELLOW, RoadMap, WorldState

SKY = (150, 190, 235)
GRASS = (96, 140, 84)
ROAD = (80, 80, 84)
WHITE = (235, 235, 235)
YELLOW = (235, 200, 30)
VEHICLE = np.array([60, 110, 220], dtype=float)
# faces front, right, rear, left (box_corners' order): ends lighter than the long sides
FACE_COLOURS = tuple(
    tuple(int(c) for c in np.clip(VEHICLE * shade, 0, 255)) for shade in (0.9, 0.65, 0.9, 0.65)
)
ROOF_COLOUR = tuple(int(c) for c in np.clip(VEHICLE * 1.15, 0, 255))
LIGHT_COLOURS = {LIGHT_RED: (230, 40, 40), LIGHT_YELLOW: (240, 200, 40), LIGHT_GREEN: (40, 210, 80)}
LIGHT_HEIGHT_M = 3.0
VEHICLE_HEIGHT_M = 1.5
PEDESTRIAN_HEIGHT_M = 1.7
PEDESTRIAN_COLOURS = ((200, 60, 160), (170, 50, 135), (200, 60, 160), (170, 50, 135))  # magenta
MARKING_WIDTH_M = 0.15  # white lane markings
GUIDE_WIDTH_M = 0.3  # the follow-line circuit's yellow line is painted wider
MASKS = ("left_line", "right_line", "guide_line")


def _near_clip_m(model: PinholeModel) -> float:
    """Forward distance below which ground is cut: the camera's near plane, or farther where the
    ground there would project more than a few rows below the image (a ground point's row depends
    on its forward distance only, so one cut on x also bounds the rows OpenCV fills)."""
    below_image = float(model.distance_of_row(model.height - 1 + 4.0))
    return max(model.forward_m + model.near_m, below_image if np.isfinite(below_image) else 0.0)


def _ground_polygons_batch(
    model: PinholeModel,
    positions: np.ndarray,
    headings: np.ndarray,
    groups: list[list[tuple[np.ndarray, np.ndarray]]],
) -> list[list[list[np.ndarray]]]:
    """K worlds' ground polygons (per world, groups of (world vertices one after another, counts))
    → per world and group, the fixed-point pixel polygons in sight of that world's ego at
    ``positions[k]`` (K, 2), ``headings[k]`` (K,). All worlds and groups share one transform,
    cull, clip and projection."""
    result: list[list[list[np.ndarray]]] = [[[] for _ in world_groups] for world_groups in groups]
    parts = [
        (k, g, p, c)
        for k, world_groups in enumerate(groups)
        for g, (p, c) in enumerate(world_groups)
        if len(c)
    ]
    if not parts or sum(int(c.sum()) for *_, c in parts) == 0:
        return result
    counts = np.concatenate([c for *_, c in parts])
    polygon_world = np.concatenate([np.full(len(c), k) for k, _, _, c in parts])
    polygon_group = np.concatenate([np.full(len(c), g) for _, g, _, c in parts])
    world_of_vertex = np.concatenate([np.full(len(p), k) for k, _, p, _ in parts])
    points = ego_frame(
        np.concatenate([p for *_, p, _ in parts]), positions[world_of_vertex], headings[world_of_vertex]
    )
    near = _near_clip_m(model)
    # cull polygons wholly outside one side of the view wedge (behind, left or right of it)
    slope = model.width / 2 / model.focal_px
    reach = (points[:, 0] - model.forward_m) * slope + 1.0
    outside = np.stack([points[:, 0] < near, points[:, 1] > reach, -points[:, 1] > reach], axis=1)
    starts = np.cumsum(counts) - counts
    culled = np.logical_and.reduceat(outside, starts, axis=0).any(axis=1)
    if culled.any():
        points = points[np.repeat(~culled, counts)]
        counts = np.where(culled, 0, counts)
    # clip on x (forward) with the row clipper: it reads column 1, so hand it (y, x)
    swapped = points[:, ::-1]
    if len(swapped) and swapped[:, 1].min() < near:
        swapped, counts = _clip_half_plane(swapped, counts, near, keep_below=False)
    pixels = fixed_point(model.project_ground(swapped[:, ::-1])) if len(swapped) else np.zeros((0, 2))
    ends = np.cumsum(counts)
    for index in np.flatnonzero(counts >= 3):
        polygon = pixels[ends[index] - counts[index] : ends[index]]
        result[polygon_world[index]][polygon_group[index]].append(polygon)
    return result


def _strip_quads(segments: np.ndarray, width_m: float | np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    """Segments (M, 2, 2) → rectangles (4·M, 2) ``width_m`` (one, or (M,) per segment) wide around
    them, and counts (M,)."""
    start, end = segments[:, 0], segments[:, 1]
    direction = end - start
    length = np.maximum(np.hypot(direction[:, 0], direction[:, 1]), 1e-9)
    half_width = np.reshape(np.asarray(width_m, dtype=float) / 2, (-1, 1))
    normal = np.stack([-direction[:, 1], direction[:, 0]], axis=1) / length[:, None] * half_width
    quads = np.stack([start + normal, end + normal, end - normal, start - normal], axis=1)
    return quads.reshape(-1, 2), np.full(len(segments), 4, dtype=int)


class PaintedSegments:
    """A road's solid markings and guide lines with bounding circles, for a cheap cull per frame."""

    def __init__(self, road: RoadMap) -> None:
        self.solid = road.derived(solid_markings, solid_markings)
        self.guide = GuideSegments(road).segments
        self.circles = [_circles(segments) for segments in (self.solid, self.guide)]

    def near_masks(self, positions: np.ndarray, reach: float) -> tuple[np.ndarray, np.ndarray]:
        """Masks (W, M) of the (solid, guide) segments whose bounding circle comes within ``reach``
        of each of W ``positions`` (W, 2)."""
        masks = []
        for centre, radius in self.circles:
            offset = centre[None] - positions[:, None]  # (W, M, 2)
            masks.append(np.hypot(offset[..., 0], offset[..., 1]) <= reach + radius)
        return masks[0], masks[1]


PIECE_STATIONS = 2  # lane pieces span this many of the road map's 2 m stations


class LanePieces(LanePolygons):
    """A road's lane polygons cut into quadrilaterals between consecutive stations (a polygon made of a
    left edge and its right edge reversed, as ``RoadMap`` stores them), so that only the pieces in
    the camera's view are clipped and drawn; pieces are stored one after another with counts."""

    def __init__(self, road: RoadMap) -> None:
        pieces = []
        for polygon in road.lane_polygons:
            polygon = np.asarray(polygon, dtype=float).reshape(-1, 2)
            half = len(polygon) // 2
            if len(polygon) % 2 or half < 2:
                pieces.append(polygon)
                continue
            left, right = polygon[:half], polygon[half:][::-1]
            # every other station: 4 m chords of curved lanes sag by L²/8R, under 7 cm for R > 30 m
            keep = np.unique(np.r_[np.arange(0, half, PIECE_STATIONS), half - 1])
            left, right = left[keep], right[keep]
            quads = np.stack([left[:-1], left[1:], right[1:], right[:-1]], axis=1)
            pieces.extend(quads)
        self._index(pieces)


def _circles(segments: np.ndarray) -> tuple[np.ndarray, np.ndarray]:
    return segments.mean(axis=1), np.hypot(*(segments[:, 1] - segments[:, 0]).T) / 2


def _fill_strips(image: np.ndarray, polygons: list[np.ndarray], colour) -> None:
    """Fill clipped strip pieces one by one (one ``fillPoly`` call would XOR where lines converge
    towards the horizon); each piece is a clipped rectangle, hence convex: the fast fill."""
    for polygon in polygons:
        cv2.fillConvexPoly(image, polygon, colour, cv2.LINE_8, SHIFT)


def _offset_polyline(polyline: np.ndarray, offset_m: float) -> np.ndarray:
    """Segments (M, 2, 2) of ``polyline`` shifted ``offset_m`` to their right (+) or left (−)."""
    segments = polyline_segments(polyline)
    direction = segments[:, 1] - segments[:, 0]
    length = np.maximum(np.hypot(direction[:, 0], direction[:, 1]), 1e-9)
    right = np.stack([-direction[:, 1], direction[:, 0]], axis=1) / length[:, None]  # y is to the right
    return segments + (offset_m * right)[:, None, :]


def ego_lane_lines(world: WorldState) -> tuple[np.ndarray, np.ndarray]:
    """The ego lane's left and right boundaries as segments (M, 2, 2): the route's centre line
    (the ego's planned lane) shifted by half the lane width to each side."""
    half = world.ego.lane_width_m / 2
    route = np.asarray(world.route.polyline, dtype=float)
    return _offset_polyline(route, -half), _offset_polyline(route, half)


def _road_user_quads(
    model: PinholeModel, batch: WorldBatch
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """The road users in front of each camera, for all K worlds at once: fixed-point pixels (U, 8, 2)
    of their boxes' bottom then top corners, the (U, 4) side faces seen, (U,) pedestrian flags and
    distances, and the (K + 1,) offsets of each world's users in those rows."""
    users, valid = batch.road_users()  # vehicles, then pedestrians
    position, heading = batch.ego.position[:, None, None], batch.ego.heading[:, None, None]
    corners = ego_frame(box_corners(users[..., [0, 1, 2, 4, 5]]), position, heading)  # (K, N + P, 4, 2)
    distance = np.hypot(*np.moveaxis(corners.mean(axis=2) - [model.forward_m, 0.0], -1, 0))  # (K, M)
    ahead = (
        valid
        & (corners[..., 0] > model.forward_m + model.near_m).all(axis=-1)
        & (distance < model.max_range_m)
    )
    world, slot = np.nonzero(ahead)  # world-major, each world's users in order
    corners, distance = corners[world, slot], distance[world, slot]
    is_pedestrian = slot >= batch.vehicles.shape[1]  # the slots after the vehicles'
    count = len(corners)
    bottom = np.concatenate([corners, np.zeros((count, 4, 1))], axis=2)
    heights = np.where(is_pedestrian, PEDESTRIAN_HEIGHT_M, VEHICLE_HEIGHT_M)
    top = np.concatenate([corners, np.broadcast_to(heights[:, None, None], (count, 4, 1))], axis=2)
    pixels = fixed_point(model.project(np.concatenate([bottom, top], axis=1)))  # (U, 8, 2)
    middle = (corners + corners[:, FOLLOWING]) / 2
    outward = middle - corners.mean(axis=1, keepdims=True)
    camera = np.array([model.forward_m, 0.0])
    facing = np.einsum("nki,nki->nk", outward, camera - middle) > 0  # (U, 4) faces seen
    offsets = np.r_[0, np.cumsum(ahead.sum(axis=1))]
    return pixels, facing, is_pedestrian, distance, offsets


FOLLOWING = np.array([1, 2, 3, 0])  # the corner after each of ``box_corners``' four


def _draw_road_users(
    image: np.ndarray, pixels: np.ndarray, facing: np.ndarray, is_pedestrian: np.ndarray, distance: np.ndarray
) -> None:
    """One world's road users in front of its camera (rows of ``_road_user_quads``) as boxes, far to
    near: visible side faces shaded by orientation, then the top; pedestrians are tall, narrow and
    coloured apart."""
    for user in np.argsort(-distance):  # painter's order: far to near
        faces, roof = (PEDESTRIAN_COLOURS, PEDESTRIAN_COLOURS[0]) if is_pedestrian[user] else (
            FACE_COLOURS, ROOF_COLOUR)  # fmt: skip
        for face in np.flatnonzero(facing[user]):
            quad = pixels[user, [face, FOLLOWING[face], FOLLOWING[face] + 4, face + 4]]
            cv2.fillConvexPoly(image, quad, faces[face], cv2.LINE_8, SHIFT)
        cv2.fillConvexPoly(image, pixels[user, 4:], roof, cv2.LINE_8, SHIFT)


def _traffic_light_marks(
    model: PinholeModel, batch: WorldBatch
) -> tuple[np.ndarray, np.ndarray, np.ndarray, np.ndarray]:
    """Traffic lights (K, L) as a pole and a lamp, for all K worlds at once: the (K, L) mask of those
    drawn, integer pixels (K, L, 2, 2) of each pole's foot and lamp, and the lamps' radii (K, L)."""
    local = ego_frame(batch.traffic_lights[..., :2], batch.ego.position[:, None], batch.ego.heading[:, None])
    x, y = local[..., 0], local[..., 1]
    seen = (
        batch.light_valid & (x > model.forward_m + model.near_m) & (x < model.forward_m + model.max_range_m)
    )
    foot = np.stack([x, y, np.zeros_like(x)], axis=-1)
    points = np.stack([foot, foot + [0.0, 0.0, LIGHT_HEIGHT_M]], axis=-2)  # (K, L, 2, 3)
    # the camera is pitched down: a lamp just past the ground near plane can be behind the image
    # plane, where the projection flips and overflows OpenCV's int32 pixels
    seen &= model.to_camera(points)[..., 2].min(axis=-1) > model.near_m
    pixels = np.round(np.where(seen[..., None, None], model.project(points), 0.0)).astype(int)
    radius = np.maximum(np.round(0.3 * model.focal_px / np.maximum(x - model.forward_m, 1e-3)), 1)
    return seen, pixels, np.where(seen, radius, 1).astype(int), batch.traffic_lights[..., 3]


def _ground_layers(batch: WorldBatch, model: PinholeModel) -> list[tuple[tuple, list]]:
    """Per world, its road's (lane polygons (P, 2) with counts) and painted strips as
    [(segments, width, colour)] within the camera's reach of its ego; culled map by map for all
    the worlds on that map at once."""
    reach = model.forward_m + model.max_range_m
    layers: list = [None] * batch.num_worlds
    for index, road in enumerate(batch.roads):
        worlds = np.flatnonzero(batch.road_index == index)
        positions = batch.ego.position[worlds]  # (W, 2)
        lanes: LanePieces = road.derived(LanePieces, LanePieces)
        offset = lanes.centres[None] - positions[:, None]
        visible = np.hypot(offset[..., 0], offset[..., 1]) <= reach + lanes.radii  # (W, P)
        painted: PaintedSegments = road.derived(PaintedSegments, PaintedSegments)
        solid_near, guide_near = painted.near_masks(positions, reach)
        dashes = road.derived(DashedMarkings, DashedMarkings).dashes_around(positions, reach)
        if len(road.crossings):
            stripes = road.derived(zebra_boxes, zebra_boxes)
            along = np.column_stack([np.cos(stripes[:, 2]), np.sin(stripes[:, 2])]) * stripes[:, 3:4] / 2
            zebra = np.stack([stripes[:, :2] - along, stripes[:, :2] + along], axis=1)
            zebra_near = segments_near(zebra, positions, reach)  # (W, S)
        for w, k in enumerate(worlds):
            lane_points, lane_counts = lanes.vertices[visible[w][lanes.owner]], lanes.counts[visible[w]]
            strips = [
                (np.concatenate([painted.solid[solid_near[w]], dashes[w]]), MARKING_WIDTH_M, WHITE),
                (painted.guide[guide_near[w]], GUIDE_WIDTH_M, YELLOW),
            ]
            if len(road.crossings):
                strips.append((zebra[zebra_near[w]], ZEBRA_STRIPE_M[0], WHITE))
            layers[k] = ((lane_points, lane_counts), strips)
    return layers


def render_camera(world: WorldState, model: PinholeModel) -> np.ndarray:
    """The camera's RGB uint8 image (H, W, 3) of one world."""
    image = np.empty((1, model.height, model.width, 3), dtype=np.uint8)
    draw_camera(WorldBatch.stack([world]), model, image)
    return image[0]


def draw_camera(batch: WorldBatch, model: PinholeModel, out: np.ndarray) -> None:
    """Draw the K worlds' camera images into ``out`` (K, H, W, 3) uint8."""
    layers = _ground_layers(batch, model)
    # every world's painted strips as rectangles in one pass, then back to their world and kind
    strips = [(segments, width) for _, world_strips in layers for segments, width, _ in world_strips]
    widths = np.concatenate([np.full(len(segments), width) for segments, width in strips])
    quads, _ = _strip_quads(np.concatenate([segments for segments, _ in strips]).reshape(-1, 2, 2), widths)
    sizes = np.cumsum([len(segments) for segments, _ in strips])
    quads = iter(np.split(quads.reshape(-1, 4, 2), sizes[:-1]))
    groups = [
        [lanes] + [(next(quads).reshape(-1, 2), np.full(len(s), 4, dtype=int)) for s, _, _ in world_strips]
        for lanes, world_strips in layers
    ]
    projected = _ground_polygons_batch(model, batch.ego.position, batch.ego.heading, groups)
    users, facing, is_pedestrian, distance, offsets = _road_user_quads(model, batch)
    lights_seen, light_pixels, radii, states = _traffic_light_marks(model, batch)
    out[:] = GRASS
    out[:, : int(np.clip(np.ceil(model.horizon_row), 0, model.height))] = SKY
    for k in range(batch.num_worlds):  # one OpenCV raster per world
        image = out[k]
        _fill_strips(image, projected[k][0], ROAD)  # lane pieces are quads: convex, also once clipped
        for polygons, (_, _, colour) in zip(projected[k][1:], layers[k][1], strict=True):
            _fill_strips(image, polygons, colour)
        mine = slice(offsets[k], offsets[k + 1])
        _draw_road_users(image, users[mine], facing[mine], is_pedestrian[mine], distance[mine])
        for light in np.flatnonzero(lights_seen[k]):
            foot, lamp = (tuple(point) for point in light_pixels[k, light].tolist())
            cv2.line(image, foot, lamp, (40, 40, 40), 1)
            colour = LIGHT_COLOURS.get(int(states[k, light]), (200, 200, 200))
            cv2.circle(image, lamp, int(radii[k, light]), colour, -1, cv2.LINE_8)


def render_masks(world: WorldState, model: PinholeModel) -> np.ndarray:
    """Ground-truth masks (3, H, W) uint8 in {0, 1}: the ego lane's left line, its right line (both
    continuous, as wide as a painted marking) and the guide line, in the camera's projection."""
    masks = np.zeros((len(MASKS), model.height, model.width), dtype=np.uint8)
    position = np.asarray(world.ego.position, dtype=float)
    left, right = ego_lane_lines(world)
    guide = world.road.derived(GuideSegments, GuideSegments).segments
    widths = (MARKING_WIDTH_M, MARKING_WIDTH_M, GUIDE_WIDTH_M)
    reach = model.forward_m + model.max_range_m  # the camera's drawing range
    groups = [
        _strip_quads(s[segments_near(s, position, reach)], w)
        for s, w in zip((left, right, guide), widths, strict=True)
    ]
    positions, headings = np.reshape(position, (1, 2)), np.reshape(world.ego.heading, 1)
    for channel, polygons in enumerate(_ground_polygons_batch(model, positions, headings, [groups])[0]):
        _fill_strips(masks[channel], polygons, 1)
    return masks


class Camera(Sensor):
    """On-board RGB camera, channels last ``(height, width, 3)`` uint8 (see ``render_camera``).

    :param width: image width in pixels.
    :param height: image height in pixels.
    :param fov_deg: horizontal field of view.
    :param height_m: mounting height.
    :param pitch_deg: downward pitch.
    :param forward_m: mounting point ahead of the ego's centre.
    :param max_range_m: drawing distance.
    """

    name = "camera"
    help = "84x84 RGB first-person pinhole camera (fov, height, pitch configurable)"

    def __init__(
        self,
        *,
        width: int = 84,
        height: int = 84,
        fov_deg: float = 90.0,
        height_m: float = 1.5,
        pitch_deg: float = 15.0,
        forward_m: float = 1.0,
        max_range_m: float = 50.0,
    ) -> None:
        self.model = PinholeModel(
            int(width), int(height), float(fov_deg), float(height_m), float(pitch_deg), float(forward_m),
            float(max_range_m),
        )  # fmt: skip
        self._space = spaces.Box(0, 255, shape=(self.model.height, self.model.width, 3), dtype=np.uint8)

    def _observe(self, batch: WorldBatch, out: np.ndarray) -> None:
        draw_camera(batch, self.model, out)

    def masks(self, world: WorldState) -> np.ndarray:
        """Ground-truth line masks (3, H, W) for ``world`` (see ``render_masks``)."""
        return render_masks(world, self.model)
