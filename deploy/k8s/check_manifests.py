#!/usr/bin/env python3
"""Validates Kubernetes manifests offline (deploy/check.sh runs it in a venv):
built-in kinds with kubernetes-validate --strict against the given Kubernetes version, the
custom resources rayfarm ships (KEDA's ScaledObject, the Prometheus Operator's ServiceMonitor)
against the minimal schemas in deploy/k8s/schemas/. A kind neither knows fails, so nothing
passes unchecked.

  check_manifests.py --kubernetes-version 1.27 FILE.yaml...
"""
import argparse
import json
import os
import subprocess
import sys
import tempfile

import jsonschema
import yaml

HERE = os.path.dirname(os.path.abspath(__file__))
CUSTOM = {
    ("keda.sh/v1alpha1", "ScaledObject"): "scaledobject.schema.json",
    ("monitoring.coreos.com/v1", "ServiceMonitor"): "servicemonitor.schema.json",
}


def check_custom(doc, where):
    schema = json.load(open(os.path.join(HERE, "schemas", CUSTOM[(doc["apiVersion"], doc["kind"])])))
    errors = sorted(jsonschema.Draft202012Validator(schema).iter_errors(doc), key=lambda e: list(e.path))
    problems = [f"{where}: {'/'.join(map(str, e.path)) or '(top)'}: {e.message}" for e in errors]
    spec = doc.get("spec", {})
    if doc["kind"] == "ScaledObject" and spec.get("minReplicaCount", 0) > spec.get("maxReplicaCount", 100):
        problems.append(f"{where}: minReplicaCount is above maxReplicaCount")
    return problems


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--kubernetes-version", required=True)
    ap.add_argument("files", nargs="+")
    args = ap.parse_args()
    problems, builtin = [], []
    for path in args.files:
        with open(path) as f:
            for i, doc in enumerate(yaml.safe_load_all(f)):
                if not doc:
                    continue
                where = f"{path}: document {i + 1} ({doc.get('kind')}/{doc.get('metadata', {}).get('name')})"
                if (doc.get("apiVersion"), doc.get("kind")) in CUSTOM:
                    problems += check_custom(doc, where)
                    print(f"checked {where} against its minimal schema")
                else:
                    builtin.append(doc)
    if builtin:
        with tempfile.NamedTemporaryFile("w", suffix=".yaml", delete=False) as tmp:
            yaml.safe_dump_all(builtin, tmp)
        try:
            r = subprocess.run(["kubernetes-validate", "--strict", "-k", args.kubernetes_version, tmp.name],
                               capture_output=True, text=True)
        finally:
            os.unlink(tmp.name)
        out = (r.stdout + r.stderr).replace(tmp.name, "manifests")
        print(out, end="")
        if r.returncode != 0:
            problems.append(f"kubernetes-validate failed (exit {r.returncode})")
        if "Couldn't find schema" in out:
            problems.append("a kind that neither kubernetes-validate nor deploy/k8s/schemas knows")
    for p in problems:
        print("error: " + p, file=sys.stderr)
    return 1 if problems else 0


if __name__ == "__main__":
    sys.exit(main())
