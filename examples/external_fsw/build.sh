#!/bin/sh
# Generate the Python protobuf code of the swarmhil wire contract for this flight computer.
#   ./build.sh [PROTO [OUTDIR]]     default: ../../bus/swarmhil.proto -> ./build
# PROTO can be the swarmhil.proto of a join kit (DIR/external/<id>/swarmhil.proto): the same file.
# Needs grpcio-tools (its protoc) matching the protobuf runtime, e.g. `pip install -r requirements.txt`;
# PYTHON picks the interpreter (default python3).
set -eu
here=$(cd "$(dirname "$0")" && pwd)
proto=${1:-$here/../../bus/swarmhil.proto}
out=${2:-$here/build}
py=${PYTHON:-python3}
mkdir -p "$out"
"$py" -m grpc_tools.protoc -I "$(cd "$(dirname "$proto")" && pwd)" --python_out="$out" "$(basename "$proto")"
echo "wrote $out/swarmhil_pb2.py"
