"""Build step of the crease package: generates the gRPC stubs from the repository's proto/.

`pip install ./clients/python` builds in place, so ../../proto is the repository's wire
contract; CREASE_PROTO_DIR names another copy (a source tree laid out differently). The
stubs land in the build directory as the package `crease.v1` (crease_pb2, crease_pb2_grpc,
cluster_pb2, take_pb2): the proto package is `crease.v1`, so the generated imports
(`from crease.v1 import crease_pb2`) resolve inside this package.
"""

import os
from pathlib import Path

from setuptools import setup
from setuptools.command.build_py import build_py

HERE = Path(__file__).resolve().parent


def proto_dir() -> Path:
    named = os.environ.get("CREASE_PROTO_DIR")
    root = Path(named) if named else HERE.parent.parent / "proto"
    if not (root / "crease" / "v1" / "crease.proto").is_file():
        raise SystemExit(
            f"crease: the protos are not at {root}/crease/v1/crease.proto: build from the "
            "repository (`pip install ./clients/python`) or set CREASE_PROTO_DIR to its proto/ folder"
        )
    return root


class BuildWithStubs(build_py):
    """build_py, then grpcio-tools' protoc over proto/crease/v1/*.proto into the build tree."""

    def run(self) -> None:
        super().run()
        from grpc_tools import protoc  # a build requirement (pyproject.toml)
        import grpc_tools

        root = proto_dir()
        out = Path(self.build_lib)
        protos = sorted(str(p.relative_to(root)) for p in (root / "crease" / "v1").glob("*.proto"))
        include = Path(grpc_tools.__file__).parent / "_proto"
        args = [
            "grpc_tools.protoc",
            f"-I{root}",
            f"-I{include}",
            f"--python_out={out}",
            f"--pyi_out={out}",
            f"--grpc_python_out={out}",
            *protos,
        ]
        if protoc.main(args) != 0:
            raise SystemExit(f"crease: grpc_tools.protoc failed on {protos} (from {root})")
        (out / "crease" / "v1" / "__init__.py").write_text(
            '"""gRPC stubs of crease.v1, generated from proto/ when the package was built."""\n'
        )


setup(cmdclass={"build_py": BuildWithStubs})
