"""Whether a scenario's packages and obstacles can be placed the way `layout.make_layouts`
places them (`check_placement`, run on every scenario `sim.scenario` builds)."""

from __future__ import annotations

import math

from .scenario_types import PACKAGE_CLEARANCE, ROBOT_RADII, Scenario, ScenarioError


def check_placement(s: Scenario) -> None:
    """ScenarioError unless the packages and obstacles of `s` can be placed the way
    `layout.make_layouts` places them. These are necessary conditions, kept simple:

    - every obstacle fits in the arena (2 x radius < arena), and the obstacles cover at most
      half of it (count x pi x low radius^2);
    - a package's grip band meets the robot radii [0.15, 0.5] m;
    - its distance range starts outside the base (low >= base_radius + size), its nearest
      distance is inside the arena in every direction (low <= arena/2 - clearance) and its
      farthest at most reaches the corners (high <= (arena/2 - clearance) x sqrt 2), where the
      clearance is size + 0.6 m (the room a robot needs at each grip);
    - its packages, as discs of radius clearance, fit in the ring their distances allow, and all
      packages and obstacles together fit in the arena outside the base.
    """
    W, base = s.arena, s.base_radius
    lo_r, hi_r = s.obstacle_radius
    if s.obstacle_count:
        if 2 * hi_r >= W:
            raise ScenarioError(
                f"obstacles.radius: an obstacle of radius {hi_r:g} m does not fit "
                f"in a {W:g} m arena"
            )
        if s.obstacle_count * math.pi * lo_r**2 > W * W / 2:
            raise ScenarioError(
                f"obstacles: {s.obstacle_count} obstacles of radius >= {lo_r:g} m "
                f"cover more than half of the {W:g} m arena; packages could not "
                "be placed clear of them"
            )
    used = s.obstacle_count * math.pi * lo_r**2
    for i, c in enumerate(s.packages):
        w = f"packages[{i}]."
        band_lo, band_hi = c.radius_band
        if band_hi < ROBOT_RADII[0] or band_lo > ROBOT_RADII[1]:
            raise ScenarioError(
                f"{w}radius_band: [{band_lo:g}, {band_hi:g}] m holds no robot "
                f"radius (robots are {ROBOT_RADII[0]:g}-{ROBOT_RADII[1]:g} m)"
            )
        clear = c.size + PACKAGE_CLEARANCE
        d_lo, d_hi = c.distance
        if d_lo < base + c.size:
            raise ScenarioError(
                f"{w}distance: packages at {d_lo:g} m lie inside the base "
                f"(base_radius {base:g} m + size {c.size:g} m)"
            )
        if d_lo > W / 2 - clear:
            raise ScenarioError(
                f"{w}distance: {d_lo:g} m from the base centre lies outside the "
                f"arena in most directions (at most {W / 2 - clear:g} m: arena/2 "
                f"- size - {PACKAGE_CLEARANCE:g})"
            )
        if d_hi > (W / 2 - clear) * math.sqrt(2):
            raise ScenarioError(
                f"{w}distance: {d_hi:g} m lies outside the arena (at most "
                f"{(W / 2 - clear) * math.sqrt(2):.3g} m)"
            )
        need = c.count * math.pi * clear**2
        ring = min(math.pi * ((d_hi + clear) ** 2 - max(d_lo - clear, 0.0) ** 2), W * W)
        if need > ring:
            raise ScenarioError(
                f"{w}count: {c.count} packages of size {c.size:g} m do not fit "
                f"at {d_lo:g}-{d_hi:g} m from the base (they need {need:.4g} m2, "
                f"the ring holds {ring:.4g} m2)"
            )
        used += need
    if used > W * W - math.pi * base**2:
        raise ScenarioError(
            f"packages: the packages and obstacles need {used:.4g} m2, more than "
            f"the {W * W - math.pi * base**2:.4g} m2 of the arena outside the "
            "base"
        )
