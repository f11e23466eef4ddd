#!/usr/bin/env python3
"""The index maps of the Sobol sampler's joint pairs (engine/sampler.h, kJointRows): t-values and
the search that found them.

A joint pair draws Sobol dimensions 0 and 1 at L n, where n is the shuffled index of the camera
sample's first draw and L a linear map over GF(2) of the low 12 index bits, output bit j = input
bit j XOR input bits above j. With the first draw, (C0 n, C1 n, C0 L n, C1 L n) is a digital net;
this prints its t-value for 2^m samples, m = 1..12, and searches (hill climbing on L's bits) for
maps with small t at m = 3..12. Pairs 2 and 3 (the second vertex) are L_0 L_1 and L_1 L_1, which
stand with pair 1 as pairs 0 and 1 stand with the first draw; the table checks that too.

    python3 bench/joint_nets.py                  # t-values of the shipped maps
    python3 bench/joint_nets.py --search 1 300   # a search from seed 1 (the shipped pair 0)
    python3 bench/joint_nets.py --search 4 250 --against 0   # pair 1: small t with the first
                                                 # draw and with pair 0 together

t-values are a guide, not the choice: maps of equal t differ by up to 10x in the error of
veach-mis's highlight (docs/performance.md); the shipped maps were checked by renders.
"""
import argparse
import random

BITS = 12
SHIPPED = [
    [0xa27, 0x15a, 0x98c, 0xa58, 0xc30, 0x1e0, 0xc40, 0x080, 0xb00, 0xa00, 0xc00, 0x800],
    [0x3d7, 0xdda, 0x564, 0xb88, 0xa50, 0x6a0, 0xe40, 0x580, 0x900, 0x200, 0xc00, 0x800],
]


def sobol_rows(dim, m):
    """Rows of Sobol dimension 0 or 1's generator matrix for m bits: row r (the output bit of
    weight 2^-(r+1)) as a mask over index bits. Dimension 0 is the identity; dimension 1's entry
    (r, j) is binomial(j, r) mod 2 (Pascal's triangle, the matrix engine/sampler.h computes)."""
    if dim == 0:
        return [1 << r for r in range(m)]
    return [sum(1 << j for j in range(m) if (j & r) == r) for r in range(m)]


def rank(vectors):
    pivots = {}
    r = 0
    for v in vectors:
        while v:
            h = v.bit_length() - 1
            if h in pivots:
                v ^= pivots[h]
            else:
                pivots[h] = v
                r += 1
                break
    return r


def compositions(total, parts):
    if parts == 1:
        yield (total,)
        return
    for i in range(total + 1):
        for rest in compositions(total - i, parts - 1):
            yield (i,) + rest


def t_value(matrices, m):
    """The smallest t for which every elementary box of volume 2^(t-m) holds 2^t points."""
    for t in range(m + 1):
        if all(rank(sum((M[:k] for M, k in zip(matrices, comp)), [])) == m - t
               for comp in compositions(m - t, len(matrices))):
            return t
    return m


def compose(rows, L, m):
    """The rows of C L for the map L (L[j]: the input bits summed into output bit j)."""
    mask = (1 << m) - 1
    out = []
    for row in rows:
        v = 0
        for j in range(m):
            if (row >> j) & 1:
                v ^= L[j] & mask
        out.append(v)
    return out


def compose_maps(A, B, j):
    """Row j of the map A B (B first): the input bits summed into output bit j."""
    v = 0
    for i in range(BITS):
        if (A[j] >> i) & 1:
            v ^= B[i]
    return v


def pair(L, m):
    return [compose(sobol_rows(0, m), L, m), compose(sobol_rows(1, m), L, m)]


def t_values(L, against=(), ms=range(3, BITS + 1)):
    """Per m: t of (first draw, pair L), plus t of (pair A, pair L) for each A in `against`."""
    out = []
    for m in ms:
        first = [sobol_rows(0, m), sobol_rows(1, m)]
        t = t_value(first + pair(L, m), m)
        for A in against:
            t += t_value(pair(A, m) + pair(L, m), m)
        out.append(t)
    return out


def search(seed, iterations, against):
    rng = random.Random(seed)
    mask = (1 << BITS) - 1
    L = [(1 << j) | (rng.getrandbits(BITS) & ~((1 << (j + 1)) - 1) & mask) for j in range(BITS)]
    cur = t_values(L, against)
    for _ in range(iterations):
        j = rng.randrange(BITS - 1)
        i = rng.randrange(j + 1, BITS)
        trial = list(L)
        trial[j] ^= 1 << i
        t = t_values(trial, against)
        if (sum(t), max(t)) <= (sum(cur), max(cur)):
            L, cur = trial, t
    return L, cur


def main():
    ap = argparse.ArgumentParser(description=__doc__.split('\n')[0])
    ap.add_argument('--search', nargs=2, type=int, metavar=('SEED', 'ITERATIONS'))
    ap.add_argument('--against', type=int, nargs='*', default=[],
                    help='shipped pairs the searched map must also be stratified with')
    args = ap.parse_args()
    if args.search:
        L, t = search(args.search[0], args.search[1], [SHIPPED[k] for k in args.against])
        print(('t' if not args.against else 't summed over the first draw and the pairs against')
              + ' (m = 3..12):', t)
        print('rows:', ', '.join('0x%03x' % v for v in L))
        return
    print('m  t(first, pair 0)  t(first, pair 1)  t(pair 0, pair 1)  t(all six)'
          '  t(pair 1, pair 2)  t(pair 1, pair 3)')
    L2 = [compose_maps(SHIPPED[0], SHIPPED[1], j) for j in range(BITS)]
    L3 = [compose_maps(SHIPPED[1], SHIPPED[1], j) for j in range(BITS)]
    for m in range(1, BITS + 1):
        first = [sobol_rows(0, m), sobol_rows(1, m)]
        a, b = pair(SHIPPED[0], m), pair(SHIPPED[1], m)
        print('%2d %17d %17d %18d %11d %18d %18d' % (
            m, t_value(first + a, m), t_value(first + b, m), t_value(a + b, m),
            t_value(first + a + b, m), t_value(b + pair(L2, m), m), t_value(b + pair(L3, m), m)))


if __name__ == '__main__':
    main()
