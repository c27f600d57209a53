"""A bag's static transforms (tf2_msgs/TFMessage on /tf_static): the rotation that turns a
vector from one frame into another along the chain of transforms between them, which brings an
IMU's readings into the depth image's frame. A transform from `parent` (header.frame_id) to
`child` (child_frame_id) takes a point in the child's frame to the parent's: p = R p_child + t."""

from __future__ import annotations

from collections import deque

import numpy as np

TF_STATIC, TF_MESSAGE = "/tf_static", "tf2_msgs/msg/TFMessage"


def quaternion_matrix(x: float, y: float, z: float, w: float) -> np.ndarray:
    """The rotation of a quaternion (normalised first)."""
    q = np.array([x, y, z, w], np.float64)
    n = np.linalg.norm(q)
    if n < 1e-12:
        raise ValueError("a zero quaternion is no rotation")
    x, y, z, w = q / n
    return np.array([[1 - 2 * (y * y + z * z), 2 * (x * y - z * w), 2 * (x * z + y * w)],
                     [2 * (x * y + z * w), 1 - 2 * (x * x + z * z), 2 * (y * z - x * w)],
                     [2 * (x * z - y * w), 2 * (y * z + x * w), 1 - 2 * (x * x + y * y)]])


def frame_name(name: str) -> str:
    """A frame id as tf2 compares them (ROS 1's leading slash dropped)."""
    return name.lstrip("/")


def static_rotations(reader) -> dict:
    """{(parent, child): R (child's frame to the parent's)} of every transform on the bag's
    /tf_static (none when it has none; a message that cannot be read is passed over)."""
    out = {}
    for c in reader.connections:
        if c.topic != TF_STATIC or c.msgtype != TF_MESSAGE:
            continue
        for _, _, raw in reader.messages(connections=[c]):
            try:
                msg = reader.deserialize(raw, c.msgtype)
                for tf in msg.transforms:
                    q = tf.transform.rotation
                    out[(frame_name(tf.header.frame_id), frame_name(tf.child_frame_id))] = \
                        quaternion_matrix(q.x, q.y, q.z, q.w)
            except Exception:  # noqa: BLE001 - a damaged or odd message: the others may do
                continue
    return out


def rotation_between(rotations: dict, source: str, target: str) -> np.ndarray | None:
    """The rotation taking a vector in frame `source` to frame `target` along the shortest chain
    of `rotations` (static_rotations) between them, each walked either way; None when no chain
    joins them."""
    source, target = frame_name(source), frame_name(target)
    steps: dict = {}
    for (parent, child), r in rotations.items():
        steps.setdefault(child, []).append((parent, r))  # child -> parent: R
        steps.setdefault(parent, []).append((child, r.T))  # parent -> child: R^T
    seen = {source: np.eye(3)}
    todo = deque([source])
    while todo:
        frame = todo.popleft()
        if frame == target:
            return seen[frame]
        for other, r in steps.get(frame, []):
            if other not in seen:
                seen[other] = r @ seen[frame]
                todo.append(other)
    return None
