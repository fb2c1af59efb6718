"""Team designs as `summary.json` records them, for the replay page tests (tests/app and the
browser test in tests/e2e)."""

from swarmcode_torch.sim import bt


def design(effector="pincher", radius=0.3, tiers=(2, 2, 2), count=3, program="forage", **kw):
    d = dict(
        species=1,
        effector=effector,
        radius=radius,
        chassis_tier=tiers[0],
        battery_tier=tiers[1],
        motor_tier=tiers[2],
        torque_point=1.0,
        battery_point=1.0,
        dominance=0.6,
        selectivity=0.3,
        cost=123.0,
        bt=bt.template_tensor(program, 32).tolist(),
        count=count,
    )
    d.update(kw)
    return d


DESIGNS = [
    design("pincher", 0.3, count=12, species=3),
    design("suction", 0.25, count=6, program="forage_random", species=7, dominance=0.2),
    design("pincher", 0.45, (3, 3, 3), count=2, program="collaborative", species=9, dominance=0.9),
]
