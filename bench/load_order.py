#!/usr/bin/env python3
"""Which shared libraries a binary's dynamic loader spends its symbol lookups on (cmake/load_order.cmake).

    python3 bench/load_order.py build/bin/rayfarm [N]

Runs `BINARY --help` under LD_DEBUG=scopes and LD_DEBUG=bindings, then prints the N libraries
(default 30) that the most symbol bindings resolve to, each with its bindings and its place in the
global lookup scope, and the lookup steps (sum over bindings of the defining library's place:
a lookup tries the scope's libraries in order) of the present order and of the order with those N
first.
"""
import collections
import os
import re
import subprocess
import sys
import tempfile


def main():
    binary = sys.argv[1]
    n = int(sys.argv[2]) if len(sys.argv) > 2 else 30
    env = dict(os.environ, LD_DEBUG='scopes')
    out = subprocess.run([binary, '--help'], env=env, capture_output=True, text=True).stderr
    line = next(l for l in out.splitlines() if 'scope 0:' in l)
    scope = [os.path.basename(p) for p in line.split('scope 0:')[1].split()]
    with tempfile.TemporaryDirectory() as tmp:
        env = dict(os.environ, LD_DEBUG='bindings', LD_DEBUG_OUTPUT=os.path.join(tmp, 'b'))
        subprocess.run([binary, '--help'], env=env, capture_output=True)
        counts = collections.Counter()
        for name in os.listdir(tmp):
            with open(os.path.join(tmp, name)) as f:
                for l in f:
                    m = re.search(r'binding file \S+ \[0\] to (\S+) \[0\]', l)
                    if m:
                        counts[os.path.basename(m.group(1))] += 1

    def steps(order):
        place = {lib: i for i, lib in enumerate(order)}
        return sum(c * place[lib] for lib, c in counts.items() if lib in place)

    place = {lib: i for i, lib in enumerate(scope)}
    ranked = [lib for lib, _ in counts.most_common()
              if lib in place and place[lib] > 0 and not lib.startswith(('linux-vdso', 'ld-linux'))]
    for lib in ranked[:n]:
        print('%-32s %7d bindings, place %3d' % (lib, counts[lib], place[lib]))
    front = ranked[:n]
    print('%d libraries in scope, %d bindings; lookup steps: present order %d, these %d first %d' %
          (len(scope), sum(counts.values()), steps(scope), n,
           steps(scope[:1] + front + [l for l in scope[1:] if l not in front])))


if __name__ == '__main__':
    main()
