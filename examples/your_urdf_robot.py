"""Your URDF robot: an uncertain initial box -> a guaranteed enclosure, a frame, a plot.

Run: python examples/your_urdf_robot.py [path/to/robot.urdf] [--out DIR]
     (MBS_EXAMPLE_SHORT=1 or --short: a shorter horizon, as the tests run it)

Without a path it takes example-robot-data's double pendulum. The robot is checked
against Pinocchio, released at rest from q0 +- 1 mrad (q0 = 0.5, -0.3, 0.2, ... rad),
and enclosed for T seconds with the default method (``method="auto"``). It prints the
enclosure at T and where the end effector can be, and writes ``enclosures.png``,
``frame_region.png`` and ``result.json`` into ``--out`` (default ``out/your_robot``).
"""

import argparse
import os
from pathlib import Path

import numpy as np

import mbs
from mbs.app.figures import fig_enclosures
from mbs.app.frame_figures import fig_frame_region
from mbs.app.results import write_result
from mbs.frames import default_frame
from mbs.simulate import simulate
from verified import Interval

ap = argparse.ArgumentParser(description=__doc__.splitlines()[0])
ap.add_argument("urdf", nargs="?", default=None, help="a URDF file (default: example-robot-data's double pendulum)")
ap.add_argument("--out", default="out/your_robot")
ap.add_argument("--short", action="store_true", help="a short horizon (also MBS_EXAMPLE_SHORT=1)")
args = ap.parse_args()
short = args.short or os.environ.get("MBS_EXAMPLE_SHORT") == "1"
T = 0.1 if short else 0.5

robot = mbs.chain_from_urdf(args.urdf or mbs.robots.urdf_path("double_pendulum"))
errors = mbs.compare_with_pinocchio(robot, symbolic=False)["numeric"]
print(f"{robot.name}: {robot.n} joints {robot.joint_names}; max relative error against Pinocchio "
      f"{max(errors.values()):.1e}")

q0 = np.resize([0.5, -0.3, 0.2], robot.n)          # rad
e = 1e-3
x0 = Interval(np.r_[q0 - e, np.zeros(robot.n)], np.r_[q0 + e, np.zeros(robot.n)])
sol = simulate(robot, x0, T, output_dt=T / 5, progress=False)
print(sol.status, "|", sol.method)
for name, lo, hi in zip(sol.state_names, sol.hull[-1].lo, sol.hull[-1].hi):
    print(f"  {name:>5} at t = {T:g}: [{lo:+.6f}, {hi:+.6f}]  width {hi - lo:.2e}")

tip = default_frame(robot)                          # tool0 / tool / ee_link, else the last link's frame
where = sol.frame(tip)
print(f"frame {tip!r} at t = {T:g}: {where.position[-1]}")

out = Path(args.out)
out.mkdir(parents=True, exist_ok=True)
fig_enclosures(sol, out / "enclosures.png", title=f"{robot.name}, q(0) in q0 +- {e:g} rad")
fig_frame_region(where, out / "frame_region.png")
write_result(out / "result.json", sol)
print(f"wrote {out}/enclosures.png, frame_region.png, result.json")
