"""
Grey levels as dot density: error diffusion on the dot grid (feature mode ``tones``).

Beyond the paper (Sec. IV-C burns every dot alike): a grey picture is rendered on the grid
of Eq 17 (one cell per dot pitch r_p) by error diffusion, so the fraction of burnt cells
follows the darkness of each region. Kernels, as laser-engraver software offers them:

- ``floyd_steinberg`` (Floyd and Steinberg 1976): 7/16 right, 3/16 5/16 1/16 below;
- ``atkinson`` (Bill Atkinson, Apple): 1/8 to six neighbours, 2/8 of the error is dropped,
  so light and dark ends saturate and mid-tones look crisper;
- ``jarvis_judice_ninke`` (1976): 12 neighbours over two rows, /48; smoother, fewer worms.

Rows are scanned serpentine (alternating direction), which avoids the diagonal artefacts
of a raster scan. The grid is small (l_w / r_p = 40 cells a side for the paper's canvas),
so a plain loop is fast enough (~1 ms for 40 x 40).
"""

import numpy as np

# (row offset, column offset, weight) for a left-to-right scan; mirrored for right-to-left.
KERNELS = {
    'floyd_steinberg': ([(0, 1, 7), (1, -1, 3), (1, 0, 5), (1, 1, 1)], 16),
    'atkinson': ([(0, 1, 1), (0, 2, 1), (1, -1, 1), (1, 0, 1), (1, 1, 1), (2, 0, 1)], 8),
    'jarvis_judice_ninke': ([(0, 1, 7), (0, 2, 5),
                             (1, -2, 3), (1, -1, 5), (1, 0, 7), (1, 1, 5), (1, 2, 3),
                             (2, -2, 1), (2, -1, 3), (2, 0, 5), (2, 1, 3), (2, 2, 1)], 48),
}


def error_diffusion(darkness, kernel='floyd_steinberg', serpentine=True):
    """
    Return a boolean grid: True where a dot is burnt, from darkness in [0, 1] per cell.

    Each cell is set when its darkness plus the diffused error reaches 0.5; the error
    (wanted minus given) is spread to unvisited neighbours with the kernel's weights.
    """
    if kernel not in KERNELS:
        raise ValueError(f'unknown error-diffusion kernel {kernel!r} '
                         f'(kernels: {", ".join(KERNELS)})')
    taps, divisor = KERNELS[kernel]
    darkness = np.asarray(darkness, dtype=float)
    rows, columns = darkness.shape
    work = np.clip(darkness, 0.0, 1.0).tolist()
    dots = np.zeros((rows, columns), dtype=bool)
    for row in range(rows):
        reverse = serpentine and row % 2 == 1
        order = range(columns - 1, -1, -1) if reverse else range(columns)
        direction = -1 if reverse else 1
        line = work[row]
        for column in order:
            value = line[column]
            on = value >= 0.5
            dots[row, column] = on
            error = value - (1.0 if on else 0.0)
            if error == 0.0:
                continue
            # Taps that fall off the grid are left out and the others scaled up, so the
            # grid keeps its total darkness (the error of the last cell is the only loss).
            inside = [(row + dr, column + direction * dc, w) for dr, dc, w in taps
                      if row + dr < rows and 0 <= column + direction * dc < columns]
            total = sum(w for _, _, w in inside)
            if total == 0:
                continue
            share = error / (total if kernel != 'atkinson' else divisor)
            for r, c, w in inside:
                work[r][c] += share * w
    return dots
