#!/usr/bin/env python3
"""Drive a ScanSession from your own loop: here the simulator stands in for the robot and the
depth camera; with a real robot, replace sim.execute / sim.capture / sim.camera_pose / sim.q /
sim.put_down / sim.pick_up by your driver's calls. The session plans every view (Alg. 1), fuses
every frame hand-aware and ranks re-grasps; the loop only moves and captures.

    PYTHONPATH=build/python /usr/bin/python3 examples/python/drive_session.py [OUT_DIR]
"""
import os
import sys

import inhand

# Coarser than the defaults, so that the example runs in seconds.
OPTIONS = {"voxel_m": 0.003, "max_views": 3, "planner": {"directions": 120, "rolls": 4},
           "grasp": {"approaches": 32}, "sim": {"frame_subsample": 6}}


def scan_views(session, sim):
    """One grasp's views: move where the session says, hand it every frame on the way."""
    sim.point_camera(session.camera_pose())
    while (view := session.next_view(sim.q)) is not None:
        sim.execute(view.waypoints,
                    lambda q: session.add_frame(sim.capture(), q, sim.camera_pose()))
        record = session.finish_view()
        print(f"  view {len(session.views)}: {'initial' if record['initial'] else 'Alg. 1'}, "
              f"quality {record['quality']:.4f}, {record['frames']} frames, "
              f"mean entropy {record['mean_entropy']:.3f}")
    return session.summary().termination


def main(out_dir):
    robot = inhand.Robot.load()
    sim = inhand.Simulator(robot, "builtin:coffee_can", options=OPTIONS, seed=1, start="held")
    # The volume's centre: where the robot expects a held object (in front of the palm, frame O).
    T_O_palm = sim.grasp_T_O_palm
    centre = T_O_palm[:3, :3] @ [0, 0, robot.grasp_offset] + T_O_palm[:3, 3]
    session = inhand.ScanSession(robot, centre, options=OPTIONS)
    for grasp in range(2):
        session.begin_grasp(T_O_palm, sim.q)
        print(f"grasp {grasp + 1}: views ended with {scan_views(session, sim)}")
        if grasp == 1 or not sim.put_down():
            break
        session.end_grasp()
        candidate = session.next_grasp(sim.rest_pose, sim.q)
        if candidate is None:
            print("no grasp promises a view above t_q:", session.summary().message)
            break
        achieved = sim.pick_up(candidate.T_O_palm, candidate.q_open)
        if achieved is None:
            print("the pick-up failed")
            break
        T_O_palm = achieved
        sim.execute([sim.q, robot.with_arm_of(sim.q, candidate.q_lift)], lambda q: None)  # lift
    os.makedirs(out_dir, exist_ok=True)
    session.save(os.path.join(out_dir, "scan.inhand"))  # a checkpoint to resume from
    model = session.model()
    model.save_ply(os.path.join(out_dir, "model.ply"))
    print(f"{session.summary()}; observed {100 * model.observed_fraction():.1f}% of the surface "
          f"-> {out_dir}/model.ply")


if __name__ == "__main__":
    try:
        main(sys.argv[1] if len(sys.argv) > 1 else "session_out")
    except inhand.Error as e:
        sys.exit(f"drive_session: error: {e}")
