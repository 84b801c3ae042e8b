"""The spp checkpoints of a convergence experiment, as ``cbox converge --spp`` and the demo write them: a list
(``1,4,16``), a sequence (``1,2,4,...,256``: doubling, or ``10,20,...,50``: equal steps) or a range of powers of
two (``1-256``). Every error names the part of the text that is wrong and the forms it could take."""

from __future__ import annotations

import re


#: More checkpoints than this is a typo (``1,2,...,100000``), not an experiment; refused before expanding it.
MAX_CHECKPOINTS = 1000
_SPP_FORMS = "a list (1,4,16), a sequence (1,2,4,...,256 or 10,20,...,50) or a range of powers of two (1-256)"


def parse_spp_list(text: str) -> list[int]:
    """``--spp`` of ``cbox converge`` → the sorted spp checkpoints; ValueError saying why not, never a guess.

    - ``1,4,16``: exactly those spp, in any order, none twice;
    - ``1,2,4,...,256``: the numbers before ``...`` (two or more, all with one
      constant ratio, or all with one constant difference: ``10,20,...,50``)
      continued to the last number, which they must reach exactly; two
      numbers that allow both (``1,2,...,8``: ×2 or +1) are refused as
      ambiguous;
    - ``1-256``: the powers of two from the first to the last, which must
      both be powers of two.
    """
    t = text.replace(" ", "").replace("…", "...")
    where = f"spp list {text!r}"
    if not t:
        raise ValueError(f"{where}: empty; give {_SPP_FORMS}")
    if "-" in t.lstrip("-+") and "," not in t:
        out = _spp_range(t, where)
    elif "..." in t.split(","):
        out = _spp_sequence(t.split(","), where)
    else:
        out = [_spp(p, where) for p in t.split(",")]
        if twice := sorted({n for n in out if out.count(n) > 1}):
            raise ValueError(f"{where}: {', '.join(map(str, twice))} listed twice")
    if len(out) > MAX_CHECKPOINTS:
        raise ValueError(f"{where}: {len(out)} checkpoints; at most {MAX_CHECKPOINTS}")
    return sorted(out)


def _spp(part: str, where: str) -> int:
    if not re.fullmatch(r"[-+]?\d+", part):
        raise ValueError(f"{where}: {part!r} is not a whole number; give {_SPP_FORMS}")
    if int(part) < 1:
        raise ValueError(f"{where}: every spp must be >= 1")
    return int(part)


def _is_power_of_two(n: int) -> bool:
    return n >= 1 and n & (n - 1) == 0


def _spp_range(t: str, where: str) -> list[int]:
    """``A-B``: the powers of two from A to B, both powers of two (``3-20`` is refused, not rounded)."""
    ends = t.split("-")
    if len(ends) != 2:
        raise ValueError(f"{where}: a range is A-B (e.g. 1-256); give {_SPP_FORMS}")
    lo, hi = (_spp(e, where) for e in ends)
    if lo > hi:
        raise ValueError(f"{where}: the range runs backwards; give {hi}-{lo}")
    if not_powers := [n for n in (lo, hi) if not _is_power_of_two(n)]:
        inner_lo, inner_hi = 1 << (lo - 1).bit_length(), 1 << (hi.bit_length() - 1)
        hint = f"{inner_lo}-{inner_hi} for the powers of two in between, or " if inner_lo <= inner_hi else ""
        raise ValueError(f"{where}: a range A-B means the powers of two from A to B, so both must be powers of "
                         f"two ({' and '.join(map(str, not_powers))} {'is' if len(not_powers) == 1 else 'are'} not); "
                         f"give {hint}a list or a sequence of the spp you want")
    return [1 << k for k in range(lo.bit_length() - 1, hi.bit_length())]


def _spp_sequence(parts: list[str], where: str) -> list[int]:
    """``A,B[,C...],...,Z``: continued by the one constant ratio or difference of the numbers before ``...``."""
    if parts.count("...") != 1 or parts[-2] != "...":
        raise ValueError(f"{where}: '...' goes once, just before the last number (1,2,4,...,256)")
    head, last = [_spp(p, where) for p in parts[:-2]], _spp(parts[-1], where)
    if len(head) < 2:
        raise ValueError(f"{where}: give at least two numbers before '...' to set the step (1,2,4,...,256)")
    if any(b <= a for a, b in zip(head, head[1:])) or last < head[-1]:
        raise ValueError(f"{where}: a sequence must increase")
    ratio, diff = head[1] // head[0], head[1] - head[0]
    ways = {}  # how the head goes on -> (the numbers it gives up to the first >= last, counted or listed)
    if all(b % a == 0 and b // a == ratio for a, b in zip(head, head[1:])):
        seq = list(head)
        while seq[-1] < last:  # ratio >= 2: a few dozen steps at most
            seq.append(seq[-1] * ratio)
        ways[f"×{ratio}"] = seq
    if all(b - a == diff for a, b in zip(head, head[1:])):
        below = head[-1] + (last - head[-1]) // diff * diff  # not listed: 1,2,...,10**9 must not take minutes
        ways[f"+{diff}"] = [below] if below == last else [below, below + diff]
    if not ways:
        raise ValueError(f"{where}: the numbers before '...' have neither one constant ratio nor one constant "
                         "difference (1,2,4,...,256 or 10,20,...,50)")
    reaching = [how for how, seq in ways.items() if seq[-1] == last]
    if len(reaching) > 1 and last > head[-1]:
        raise ValueError(f"{where}: ambiguous, it can go on ×{ratio} or +{diff}; give a third number: "
                         f"{head[0]},{head[1]},{head[1] * ratio},...,{last} or "
                         f"{head[0]},{head[1]},{head[1] + diff},...,{last}")
    if not reaching:
        how = " or ".join(f"{how} passes from {seq[-2]} to {seq[-1]}" for how, seq in ways.items())
        raise ValueError(f"{where}: the sequence never reaches {last}: {how}")
    if reaching[0].startswith("×"):
        return ways[reaching[0]]
    count = len(head) + (last - head[-1]) // diff
    if count > MAX_CHECKPOINTS:
        raise ValueError(f"{where}: {count} checkpoints; at most {MAX_CHECKPOINTS}")
    return list(range(head[0], last + 1, diff))
