"""A toy dual-grasp predictor: both hands on the object's top, near the two ends of its longer
horizontal side, approaching from above and closing across it."""

from typing import Any

import numpy as np

from dataset_gen.grasps.gripper import PANDA


def predict(observation: dict[str, Any]) -> tuple[np.ndarray, np.ndarray]:
    low, high = observation["bounds"]  # the object's box, object frame (m)
    centre, size = (low + high) / 2, high - low
    along = int(np.argmax(size[:2]))  # the hands sit near the two ends of this axis
    closing = np.zeros(3)
    closing[1 - along] = 1.0  # +x of the grasp frame: the jaws close across the object
    approach = np.array([0.0, 0.0, -1.0])  # +y of the grasp frame: from above
    rotation = np.column_stack([closing, approach, np.cross(closing, approach)])
    poses = []
    for offset in np.linspace(0.2, 0.45, 5):  # five dual grasps, from the middle outwards
        pair = []
        for sign in (-1.0, 1.0):
            grasp_centre = centre.copy()
            grasp_centre[along] += sign * offset * size[along]
            grasp_centre[2] = high[2] - 0.02  # 2 cm below the top
            pose = np.eye(4)
            pose[:3, :3] = rotation
            pose[:3, 3] = grasp_centre - PANDA.contact_depth * approach  # the flange
            pair.append(pose)
        poses.append(pair)
    poses = np.array(poses)  # (K, 2, 4, 4): Panda grasp frame -> object frame (m)
    scores = -np.linspace(0.2, 0.45, 5)  # optional: higher = better
    return poses, scores
