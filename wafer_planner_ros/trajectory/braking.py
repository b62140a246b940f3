"""
The braking kernel of a controlled stop: sigma's steps of constant jerk, compiled.

``brake`` times a stop along sampled path data (``stopping``'s): sigma, the curve's own
time, from (begin, 1, 0) to rest in steps of constant jerk. Each step brakes with the
hardest jerk the jerk limits allow (``bounds``: what the acceleration limits leave of
sigma'' and the jerk limits of its rate at a state, from the path's derivatives linear
between samples), held within the deceleration the acceleration limits leave at the step's
middle and end, as long as easing off from the step's end (a constant jerk bringing sigma'
and sigma'' to zero together, ``easing``) would still keep the jerk limits all the way to
rest (``eases``); where the hardest would not, the hardest that does; then it eases off.
Where easing off stops keeping the limits is searched for among the hardest steps made
ahead (by doubling, then bisection): each try walks to rest, and trying after every step
made a stop's cost grow with the square of its steps. Steps end at the curve's breaks
(``aligned``), where its higher derivatives jump, so that the limits are checked on each
side of every jump. Plain arithmetic, compiled by numba.
"""

import numpy as np

from wafer_planner_ros.kernels import kernel

RESTED, PAST, GAVE_UP, MORE = 1, 0, -1, 2
"""How a braking ended: at rest, past the path's samples, or with no way to rest (and,
while its steps are made ahead, ``MORE``: not yet)."""
REST_SPEED = 1e-9
"""sigma' at most this with nothing left to ease off is rest (rounding)."""
TOLERANCE = 1e-9
"""Relative: how far a state may be past a bound and count as on it (``eases``)."""


@kernel(nogil=True)
def interval(lo, hi, a, b, limit):
    """Narrow [lo, hi] to the x with |b + a x| <= limit (a constraint that fixes none: kept)."""
    if abs(a) > 1e-12:
        x1, x2 = (-limit - b) / a, (limit - b) / a
        lo = max(lo, min(x1, x2))
        hi = min(hi, max(x1, x2))
    return lo, hi


@kernel(nogil=True)
def sample(values, k, f, j):
    """Return ``values[k, j]`` and ``values[k + 1, j]`` mixed by f."""
    return values[k, j] * (1.0 - f) + values[k + 1, j] * f


@kernel(nogil=True)
def place(grid, s):
    """Return (sample k, fraction to the next) of path time s; k = -1 past the samples."""
    k = np.searchsorted(grid, s, side='right') - 1
    if k < 0:
        k = 0
    if k >= len(grid) - 1:
        return -1, 0.0
    return k, (s - grid[k]) / (grid[k + 1] - grid[k])


@kernel(nogil=True)
def bounds(grid, g1, g2, g3, w1, w2, acceleration, jerk, wafer, s, v, u, h):
    """
    Return (least sigma'', most sigma'', least sigma''', most sigma''') at (s, v, u).

    The acceleration limits bound sigma'' at (s, v); the jerk limits bound a jerk held
    for ``h`` s from (s, v, u), at both ends of that step (sigma'' moves with it).
    (nan, nan, nan, nan) past the samples.
    """
    k, f = place(grid, s)
    s1 = s + h * (v + h * u / 2.0)
    v1 = v + h * u
    k1, f1 = place(grid, s1)
    if k < 0 or k1 < 0:
        return np.nan, np.nan, np.nan, np.nan
    ulo, uhi, jlo, jhi = -np.inf, np.inf, -np.inf, np.inf
    for j in range(3):
        a1 = sample(g1, k, f, j)
        a2 = sample(g2, k, f, j)
        a3 = sample(g3, k, f, j)
        ulo, uhi = interval(ulo, uhi, a1, a2 * v * v, acceleration[j])
        jlo, jhi = interval(jlo, jhi, a1, a3 * v * v * v + 3.0 * a2 * v * u, jerk[j])
        # At the step's end, where sigma'' has become u + h j.
        b1, b2, b3 = sample(g1, k1, f1, j), sample(g2, k1, f1, j), sample(g3, k1, f1, j)
        jlo, jhi = interval(jlo, jhi, b1 + 3.0 * b2 * v1 * h,
                            b3 * v1 * v1 * v1 + 3.0 * b2 * v1 * u, jerk[j])
    for j in range(2):
        if np.isfinite(wafer[j]):
            ulo, uhi = interval(ulo, uhi, sample(w1, k, f, j), sample(w2, k, f, j) * v * v,
                                wafer[j])
    if np.isfinite(wafer[2]):
        # |b + a u| <= L with a = w1, b = w2 v^2: a quadratic in u.
        ax, ay = sample(w1, k, f, 0), sample(w1, k, f, 1)
        bx, by = sample(w2, k, f, 0) * v * v, sample(w2, k, f, 1) * v * v
        aa, ab, bb = ax * ax + ay * ay, ax * bx + ay * by, bx * bx + by * by
        if aa > 1e-24:
            disc = ab * ab - aa * (bb - wafer[2] * wafer[2])
            if disc >= 0.0:
                root = np.sqrt(disc)
                ulo = max(ulo, (-ab - root) / aa)
                uhi = min(uhi, (-ab + root) / aa)
    return ulo, uhi, jlo, jhi


@kernel(nogil=True)
def advance(s, v, u, j, h):
    """Return (s, v, u) after ``h`` seconds of constant jerk j."""
    return (s + h * (v + h * (u / 2.0 + h * j / 6.0)), v + h * (u + h * j / 2.0), u + h * j)


@kernel(nogil=True)
def aligned(breaks, s, v, u, h):
    """
    Return a step no longer than ``h`` from (s, v, u) that ends at the next break, if any.

    At one of the curve's breaks its higher derivatives jump: a step that ends there
    checks the limits on each side of it at the step's ends. A break only a tenth of the
    step ahead is crossed (its side is checked within a hair of the step's start).
    """
    k = np.searchsorted(breaks, s, side='right')
    if k >= len(breaks):
        return h
    gap = breaks[k] - s
    reach = h * (v + h * u / 2.0)
    if reach <= gap or gap < 0.1 * reach:
        return h
    if u < 0.0:
        disc = v * v + 2.0 * u * gap
        to_break = (np.sqrt(disc) - v) / u if disc > 0.0 else h
    else:
        to_break = gap / v if v > 0.0 else h
    # Rounding can make a step to a break a hair ahead come out as nothing: cross it.
    return min(h, to_break) if to_break > 1e-6 * h else h


@kernel(nogil=True)
def easing(v, u):
    """Return the constant jerk that brings sigma' and sigma'' to zero together."""
    if u >= 0.0:
        return 0.0
    if v <= 0.0:
        return np.inf
    return u * u / (2.0 * v)


@kernel(nogil=True)
def eases(grid, breaks, g1, g2, g3, w1, w2, acceleration, jerk, wafer, step, s, v, u):
    """
    Return whether easing off from (s, v, u) to rest keeps every limit.

    Easing off holds the jerk ``easing`` gives; checked at every ``step`` until rest as
    the braking is (``bounds``): sigma'' within the acceleration limits, the jerk within
    the jerk limits at both ends of each step.
    """
    j = easing(v, u)
    if not (j > 0.0 and np.isfinite(j)):
        return False
    left = -u / j
    while left > 0.0:
        h = aligned(breaks, s, v, u, min(step, left))
        ulo, uhi, jlo, jhi = bounds(grid, g1, g2, g3, w1, w2, acceleration, jerk,
                                    wafer, s, v, u, h)
        # Within rounding: a braking step held on a bound ends on it up to 1e-16.
        du, dj = TOLERANCE * (1.0 + abs(u)), TOLERANCE * (1.0 + abs(j))
        if np.isnan(ulo) or not (u <= uhi + du and jlo - dj <= j <= jhi + dj):
            return False
        s, v, u = advance(s, v, u, j, h)
        left -= h
    return True


@kernel(nogil=True)
def hardest(grid, g1, g2, g3, w1, w2, acceleration, jerk, wafer, s, v, u, h):
    """
    Return (the hardest braking jerk, the most) for a step of ``h`` s from (s, v, u).

    The hardest: the least jerk the jerk limits allow, held within the deceleration the
    acceleration limits leave at the step's middle and end (where the limits along the path
    turn, an end alone lets the middle pass them). The most: the most jerk the jerk limits
    allow. (nan, nan) past the samples.
    """
    ulo, uhi, jlo, jhi = bounds(grid, g1, g2, g3, w1, w2, acceleration, jerk, wafer,
                                s, v, u, h)
    if np.isnan(ulo):
        return np.nan, np.nan
    least, most = -np.inf, np.inf
    for part in (0.5, 1.0):
        c = part * h
        s1, v1, _ = advance(s, v, u, jlo, c)
        lo1, hi1, _, _ = bounds(grid, g1, g2, g3, w1, w2, acceleration, jerk, wafer,
                                s1, v1, u, 0.0)
        if not np.isnan(lo1):
            least = max(least, (lo1 - u) / c)
            most = min(most, (min(hi1, 0.0) - u) / c)
    return min(max(jlo, least), most, jhi), jhi


@kernel(nogil=True)
def eases_from(grid, breaks, g1, g2, g3, w1, w2, acceleration, jerk, wafer, step, states,
               k):
    """Return whether easing off from ``states[k]`` keeps every limit (moving there)."""
    s, v, u = states[k, 0], states[k, 1], states[k, 2]
    return v > 0.0 and eases(grid, breaks, g1, g2, g3, w1, w2, acceleration, jerk, wafer,
                             step, s, v, u)


@kernel(nogil=True)
def bisected(grid, breaks, g1, g2, g3, w1, w2, acceleration, jerk, wafer, step, states,
             low, high, low_eases):
    """
    Return (low, high) one state apart, between the ``low`` and ``high`` given.

    Easing off keeps the limits from ``states[low]`` if ``low_eases`` (``eases_from``),
    from ``states[high]`` if not; bisection keeps it so.
    """
    while high - low > 1:
        middle = (low + high) // 2
        if eases_from(grid, breaks, g1, g2, g3, w1, w2, acceleration, jerk, wafer, step,
                      states, middle) == low_eases:
            low = middle
        else:
            high = middle
    return low, high


@kernel(nogil=True)
def brake(grid, breaks, g1, g2, g3, w1, w2, acceleration, jerk, wafer, step, halvings,
          begin, horizon, starts, jerks, states):
    """
    Fill the stop's phases from (begin, 1, 0); return (phases, how it ended).

    How it ended: ``RESTED``, ``PAST`` the samples, or ``GAVE_UP`` (no way to rest, or
    still braking ``horizon`` s after ``begin``: a stop that would rest later is not wanted).

    Each step of ``step`` s brakes with the hardest jerk (``hardest``) as long as easing off
    from the step's end still keeps every limit (``eases``); where it would not, the
    hardest braking that does (halving); once none does, easing off begins where it
    still did (braking on while it has not yet: at first, with no deceleration, there is
    nothing to ease off), its jerk constant, its last step as long as it takes.

    Where easing off stops keeping the limits is searched for, not tried after every step
    (each try is a walk to rest): the hardest steps are made ahead as the search needs
    them, easing off is tried from the ends of the steps 1, 2, 4, 8, ... after the first
    where it keeps the limits, and the first where it does not is found between the last
    two tried by bisection. Where the tries keep the limits up to a step and no further,
    that is the step trying every one finds; otherwise it is a later one, from which
    easing off keeps them as well.
    """
    starts[0] = 0.0
    states[0, 0], states[0, 1], states[0, 2] = begin, 1.0, 0.0
    n = 0
    can_ease = False  # whether easing off from states[n] keeps every limit
    while True:
        made, ended = n, MORE
        # The first state from which easing off keeps the limits (searched for like the
        # last, below: at the steps 1, 2, 4, ... after n, then by bisection).
        first = n
        if not can_ease:
            before, gap = n, 1
            while True:
                made, ended = _ahead(grid, breaks, g1, g2, g3, w1, w2, acceleration, jerk,
                                     wafer, step, horizon, starts, jerks, states, made,
                                     ended, before + gap)
                first = min(before + gap, made)
                if first == before:
                    first = made + 1  # from no state made
                    break
                if eases_from(grid, breaks, g1, g2, g3, w1, w2, acceleration, jerk,
                              wafer, step, states, first):
                    break
                before, gap = first, 2 * gap
            if first <= made:
                before, first = bisected(grid, breaks, g1, g2, g3, w1, w2, acceleration,
                                         jerk, wafer, step, states, before, first, False)
        if first > made:
            if ended != RESTED:
                return made, ended  # past the samples or out of room, still braking
            # Easing off kept the limits from no state before the speed would reach zero.
            return made, GAVE_UP
        # The last state from which easing off keeps the limits: states[good].
        good, bad, gap = first, -1, 1
        while bad < 0:
            made, ended = _ahead(grid, breaks, g1, g2, g3, w1, w2, acceleration, jerk,
                                 wafer, step, horizon, starts, jerks, states, made,
                                 ended, good + gap)
            probe = min(good + gap, made)
            if probe == good:
                return made, ended  # it keeps them up to the last state made: still braking
            if eases_from(grid, breaks, g1, g2, g3, w1, w2, acceleration, jerk, wafer,
                          step, states, probe):
                good, gap = probe, 2 * gap
            else:
                bad = probe
        good, bad = bisected(grid, breaks, g1, g2, g3, w1, w2, acceleration, jerk, wafer,
                             step, states, good, bad, True)
        k = good
        if states[k + 1, 1] > 0.0:
            # Brake less in step k, as hard as still lets easing off keep every limit.
            s, v, u = states[k, 0], states[k, 1], states[k, 2]
            h = aligned(breaks, s, v, u, step)
            j = jerks[k]
            most = hardest(grid, g1, g2, g3, w1, w2, acceleration, jerk, wafer, s, v, u,
                           h)[1]
            low, high = j, min(max(easing(v, u), j), most)
            found = False
            for _ in range(halvings):
                middle_jerk = 0.5 * (low + high)
                s1, v1, u1 = advance(s, v, u, middle_jerk, h)
                if v1 > 0.0 and eases(grid, breaks, g1, g2, g3, w1, w2, acceleration,
                                      jerk, wafer, step, s1, v1, u1):
                    high, found = middle_jerk, True
                else:
                    low = middle_jerk
            if found:
                s1, v1, u1 = advance(s, v, u, high, h)
                jerks[k] = high
                starts[k + 1] = starts[k] + h
                states[k + 1, 0], states[k + 1, 1], states[k + 1, 2] = s1, v1, u1
                n, can_ease = k + 1, True
                continue
        return _eased(grid, breaks, starts, jerks, states, k, step)


@kernel(nogil=True)
def _ahead(grid, breaks, g1, g2, g3, w1, w2, acceleration, jerk, wafer, step, horizon,
           starts, jerks, states, made, ended, target):
    """
    Make the hardest steps from ``states[made]`` until ``target``; return (made, how it ended).

    ``MORE`` while steps can still be made; else ``RESTED`` (the speed at the last step's
    end, ``states[made]``, would be zero or less), ``PAST`` the samples or ``GAVE_UP`` (out
    of room, or at ``horizon``), after which nothing is made.
    """
    if ended != MORE:
        return made, ended
    while made < target:
        if made >= len(jerks) or starts[made] >= horizon:
            return made, GAVE_UP
        s, v, u = states[made, 0], states[made, 1], states[made, 2]
        h = aligned(breaks, s, v, u, step)
        j = hardest(grid, g1, g2, g3, w1, w2, acceleration, jerk, wafer, s, v, u, h)[0]
        if np.isnan(j):
            return made, PAST
        s1, v1, u1 = advance(s, v, u, j, h)
        jerks[made] = j
        starts[made + 1] = starts[made] + h
        states[made + 1, 0], states[made + 1, 1], states[made + 1, 2] = s1, v1, u1
        made += 1
        if v1 <= 0.0:
            return made, RESTED
    return made, MORE


@kernel(nogil=True)
def _eased(grid, breaks, starts, jerks, states, n, step):
    """
    Fill the phases that ease off from ``states[n]`` to rest; return (phases, how it ended).

    Constant jerk (``easing``), steps ending at the curve's breaks, the last as long as it
    takes.
    """
    s, v, u = states[n, 0], states[n, 1], states[n, 2]
    while n < len(jerks):
        j = easing(v, u)
        if not (j > 0.0 and np.isfinite(j)):
            if v > REST_SPEED:
                return n, GAVE_UP  # nothing to ease off, yet moving
            # Rounding left it a hair from rest: it is there.
            states[n, 1], states[n, 2] = 0.0, 0.0
            return n, RESTED
        h = min(aligned(breaks, s, v, u, step), -u / j)
        if place(grid, s)[0] < 0:
            return n, PAST
        s, v, u = advance(s, v, u, j, h)
        jerks[n] = j
        n += 1
        starts[n] = starts[n - 1] + h
        if h == -states[n - 1, 2] / j:
            v, u = 0.0, 0.0  # exactly at rest: what the last step reaches, up to rounding
        states[n, 0], states[n, 1], states[n, 2] = s, v, u
        if v <= 0.0 and u >= 0.0:
            states[n, 1], states[n, 2] = 0.0, 0.0
            return n, RESTED
    return n, GAVE_UP
