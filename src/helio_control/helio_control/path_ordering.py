"""
In which order to burn the dots: an open path through every dot, short in arm time.

Travel is measured in the metric the arm pays: the time of the joint-space move between
the retreat poses of two dots (the painter moves with the lens raised by delta d_lp, paper
Algorithm 1), by ``arm_motion.move_time_matrix`` from the joints the rig's IK gives for
each dot. Per-move overheads are the same for every order and live in the cycle model.

Orderings (``ORDERINGS``):

- ``paper``: grouped by u, ordered by v (Sec. IV-C), i.e. column by column, each from
  v = 0 down; for explicit points, by world x then y;
- ``nearest``: greedy nearest neighbour from the first dot of the paper order;
- ``nearest_2opt``: ``nearest`` improved by 2-opt with neighbour lists (8 nearest by time)
  and don't-look bits until no exchange shortens the path;
- ``fast_tsp`` (default): the ``fast_tsp`` library (MIT; Rust core, Or-opt and 2-opt
  local search with perturbation, LKH-style alpha-nearness candidates on larger problems,
  exact Held-Karp up to 20 nodes; releases the GIL). Its integer matrix holds the times in
  units of 0.1 ms (coarser only if a move exceeded 6.5 s).

All solvers see an open path as a cycle through one extra 'depot' node at the same cost
from every dot, so the cycle's two depot edges cost the same whatever the order and the
rest is the best open path with free ends.

Hot neighbours (issue 13, the window rule): a dot burnt right after a neighbour closer than
``separation`` would start inside the last one's hot region, where the painter must wait
for it to cool (the paper's rule, about 3 s). ``TravelMetric`` adds that wait,
``separation_penalty``, to such a step of its matrix, so every solver but ``paper`` orders
around hot neighbours when jumping elsewhere costs less than waiting; ``path_time`` stays
the arm's own time and ``close_steps`` counts the steps left closer than ``separation``.
"""

from collections import deque
import math

from helio_control.arm_motion import move_time, move_time_matrix
import numpy as np

ORDERINGS = ('paper', 'nearest', 'nearest_2opt', 'fast_tsp')
DEFAULT_ORDERING = 'fast_tsp'
NEIGHBOURS = 8
MAX_DOTS = 20_000      # a matrix of 20,000^2 float32 is 1.6 GB: refuse beyond


def default_budget(count):
    """Return the fast_tsp time budget for `count` dots [s]: 0.1 ms per dot, 0.05..0.5 s."""
    return min(0.5, max(0.05, 1e-4 * count))


class TravelMetric:
    """Move times between dots (retreat-pose joints) and world distances."""

    def __init__(self, joints, limits, points=None, separation=0.0, separation_penalty=0.0):
        """
        Joints (N x 5) [rad] of each dot's retreat pose; points (N x 2) world [m].

        A step between two dots closer than `separation` [m] costs `separation_penalty` [s]
        more in ``matrix`` (the wait for a hot neighbour to cool); it needs `points`.
        """
        self.joints = np.asarray(joints, dtype=float).reshape(-1, 5)
        self.limits = limits
        self.points = None if points is None else np.asarray(points, dtype=float)
        if len(self.joints) > MAX_DOTS:
            raise ValueError(f'{len(self.joints)} dots: at most {MAX_DOTS} can be ordered')
        if not (separation >= 0.0 and separation_penalty >= 0.0):
            raise ValueError(f'separation and its penalty must be >= 0, got {separation} m '
                             f'and {separation_penalty} s')
        if separation > 0.0 and self.points is None:
            raise ValueError('a separation between successive dots needs their points')
        self.separation = float(separation)
        self.separation_penalty = float(separation_penalty)
        self._matrix = None

    def __len__(self):
        """Return the number of dots."""
        return len(self.joints)

    def matrix(self):
        """Return the N x N move-time matrix [s] with hot-neighbour waits (float32, once)."""
        if self._matrix is None:
            self._matrix = move_time_matrix(self.joints, self.joints, self.limits)
            if self.separation > 0.0 and self.separation_penalty > 0.0:
                for start in range(0, len(self.points), 1024):       # bounded memory
                    rows = self.points[start:start + 1024]
                    close = np.hypot(rows[:, None, 0] - self.points[None, :, 0],
                                     rows[:, None, 1] - self.points[None, :, 1]) \
                        < self.separation
                    self._matrix[start:start + 1024][close] += self.separation_penalty
                np.fill_diagonal(self._matrix, 0.0)
        return self._matrix

    def close_steps(self, order):
        """Return how many successive dots along `order` are closer than `separation`."""
        order = np.asarray(order, dtype=int)
        if self.separation <= 0.0 or len(order) < 2:
            return 0
        steps = np.diff(self.points[order], axis=0)
        return int(np.sum(np.hypot(steps[:, 0], steps[:, 1]) < self.separation))

    def path_time(self, order):
        """Sum of the move times along `order` [s] (exact, float64)."""
        order = np.asarray(order, dtype=int)
        if len(order) < 2:
            return 0.0
        return float(np.sum(move_time(self.joints[order[:-1]], self.joints[order[1:]],
                                      self.limits)))

    def path_length(self, order):
        """Sum of the world distances between successive dots along `order` [m]."""
        order = np.asarray(order, dtype=int)
        if self.points is None or len(order) < 2:
            return 0.0
        steps = np.diff(self.points[order], axis=0)
        return float(np.sum(np.hypot(steps[:, 0], steps[:, 1])))


def paper_order(grid_uv=None, points=None):
    """Sec. IV-C: grouped by u (column), ordered by v within a column."""
    keys = np.asarray(grid_uv if grid_uv is not None else points, dtype=float)
    return np.lexsort((keys[:, 1], keys[:, 0]))


def nearest_order(matrix, start=0):
    """Greedy nearest neighbour on a time matrix, from `start`."""
    count = len(matrix)
    order = np.empty(count, dtype=int)
    visited = np.zeros(count, dtype=bool)
    current = start
    for step in range(count):
        order[step] = current
        visited[current] = True
        if step + 1 == count:
            break
        row = np.where(visited, np.inf, matrix[current])
        current = int(np.argmin(row))
    return order


def _reverse(tour, position, i, j):
    """Reverse the cyclic segment tour[i..j] (the shorter side of the cycle)."""
    n = len(tour)
    length = (j - i) % n + 1
    if 2 * length > n:
        i, j, length = (j + 1) % n, (i - 1) % n, n - length
    for k in range(length // 2):
        a, b = (i + k) % n, (j - k) % n
        tour[a], tour[b] = tour[b], tour[a]
        position[tour[a]] = a
        position[tour[b]] = b


def two_opt(order, matrix, neighbours=NEIGHBOURS):
    """
    Improve an open path by 2-opt moves with neighbour lists and don't-look bits.

    The path is closed through a depot node of cost 0 to every dot (so the path's ends are
    free); a move replaces edges (a, b), (c, d) by (a, c), (b, d) when that is shorter.
    """
    count = len(order)
    if count < 4:
        return np.asarray(order, dtype=int)
    depot = count
    k = min(neighbours, count - 1)
    nearest = np.argpartition(matrix, k, axis=1)[:, :k + 1]
    candidates = []
    for a in range(count):
        row = [c for c in nearest[a] if c != a]
        row.sort(key=lambda c: matrix[a, c])
        candidates.append([depot] + row[:k])

    def cost(a, b):
        if a == depot or b == depot:
            return 0.0
        return float(matrix[a, b])

    tour = [int(c) for c in order] + [depot]
    n = len(tour)
    position = [0] * n
    for index, city in enumerate(tour):
        position[city] = index
    queue = deque(int(c) for c in order)
    queued = [True] * count + [False]
    while queue:
        a = queue.popleft()
        queued[a] = False
        improved = False
        for step in (1, -1):
            b = tour[(position[a] + step) % n]
            d_ab = cost(a, b)
            for c in candidates[a]:
                d_ac = cost(a, c)
                if d_ac >= d_ab:
                    break
                d = tour[(position[c] + step) % n]
                if c == b or d == a:
                    continue
                gain = d_ab + cost(c, d) - d_ac - cost(b, d)
                if gain > 1e-7:
                    if step == 1:
                        _reverse(tour, position, position[b], position[c])
                    else:
                        _reverse(tour, position, position[a], position[d])
                    for city in (a, b, c, d):
                        if city != depot and not queued[city]:
                            queued[city] = True
                            queue.append(city)
                    improved = True
                    break
            if improved:
                break
    start = position[depot]
    return np.array(tour[start + 1:] + tour[:start], dtype=int)


def integer_matrix(matrix, unit=1e-4):
    """
    Return the open-path problem as fast_tsp's uint16 matrix with a depot, and the unit.

    Times are rounded to `unit` (0.1 ms), or to a coarser unit when the longest move would
    not fit 16 bits. The depot costs half the longest move from every dot (so the triangle
    inequality holds).
    """
    longest = float(matrix.max()) if matrix.size else 0.0
    unit = max(unit, longest / 30000.0)
    count = len(matrix)
    scaled = np.empty((count + 1, count + 1), dtype=np.uint16)
    np.rint(matrix / unit, out=scaled[:count, :count], casting='unsafe')
    depot = int(math.ceil(longest / unit / 2.0))
    scaled[count, :] = depot
    scaled[:, count] = depot
    scaled[count, count] = 0
    np.fill_diagonal(scaled, 0)
    return scaled, unit


def fast_tsp_order(matrix, budget_s=None, stop_when_converged=True):
    """Order by the fast_tsp library on the time matrix (open path via a depot)."""
    import fast_tsp

    count = len(matrix)
    if count < 3:
        return np.arange(count)
    scaled, _ = integer_matrix(matrix)
    budget = default_budget(count) if budget_s is None else float(budget_s)
    tour = fast_tsp.find_tour(scaled, budget, max_threads=1,
                              stop_when_converged=stop_when_converged)
    start = tour.index(count)
    return np.array(tour[start + 1:] + tour[:start], dtype=int)


def order_dots(metric, method=DEFAULT_ORDERING, grid_uv=None, budget_s=None):
    """
    Return the burn order (indices) of the dots of a TravelMetric by `method`.

    `grid_uv` (N x 2) gives the paper order its (u, v); without it the world points are
    used. `budget_s` is fast_tsp's time budget (default ``default_budget``).
    """
    if method not in ORDERINGS:
        raise ValueError(f'unknown ordering {method!r} (orderings: {", ".join(ORDERINGS)})')
    count = len(metric)
    if count == 0:
        return np.zeros(0, dtype=int)
    first = paper_order(grid_uv, metric.points) if (grid_uv is not None or
                                                    metric.points is not None) \
        else np.arange(count)
    if method == 'paper' or count < 3:
        return first
    matrix = metric.matrix()
    if method == 'fast_tsp':
        return fast_tsp_order(matrix, budget_s)
    order = nearest_order(matrix, int(first[0]))
    if method == 'nearest':
        return order
    return two_opt(order, matrix)
