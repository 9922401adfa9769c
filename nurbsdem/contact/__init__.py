"""Contact detection between convex NURBS bodies (paper Section 3).

* global search: :mod:`.broadphase` (bounding spheres, Eq. 3) and patch boxes;
* local search (LCP, Sec. 3.2): :func:`detect` (one pair), :func:`detect_batch` (many pairs,
  compiled and parallel), :func:`detect_wall` / :func:`detect_wall_batch` (body against a
  flat wall patch).
"""
from .detect import ContactResult, ContactTable, detect, detect_batch, table_of
from .flat_wall import detect_wall, detect_wall_batch, wall_frame

__all__ = ["ContactResult", "ContactTable", "detect", "detect_batch", "table_of",
           "detect_wall", "detect_wall_batch", "wall_frame"]
