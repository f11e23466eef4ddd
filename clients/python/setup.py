"""Generates rayfarm/_proto/rayfarm_pb2*.py from the repository's proto/rayfarm.proto at build
time (protoc + grpc_python_plugin from Debian), so the stubs always match the coordinator's
contract and load with Debian's python3-protobuf. Nothing generated is kept in the repository."""

import os
import shutil
import subprocess
import tempfile

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = os.path.dirname(os.path.abspath(__file__))
PROTO = os.path.join(HERE, "..", "..", "proto", "rayfarm.proto")


class BuildWithStubs(build_py):
    def run(self):
        super().run()
        if not os.path.isfile(PROTO):
            raise SystemExit(f"{PROTO}: not found; install from the rayfarm repository "
                             "(pip install ./clients/python)")
        plugin = shutil.which("grpc_python_plugin")
        if not shutil.which("protoc") or not plugin:
            raise SystemExit("protoc and grpc_python_plugin are needed to build the client: "
                             "sudo apt-get install protobuf-compiler protobuf-compiler-grpc")
        # The proto is staged as rayfarm/_proto/rayfarm.proto so that the generated gRPC module
        # imports its messages as rayfarm._proto.rayfarm_pb2 (inside this package).
        with tempfile.TemporaryDirectory() as stage:
            target = os.path.join(stage, "rayfarm", "_proto")
            os.makedirs(target)
            shutil.copy(PROTO, target)
            subprocess.run(["protoc", "-I", stage, f"--python_out={self.build_lib}",
                            f"--grpc_python_out={self.build_lib}",
                            f"--plugin=protoc-gen-grpc_python={plugin}",
                            os.path.join(target, "rayfarm.proto")], check=True)


setup(cmdclass={"build_py": BuildWithStubs})
