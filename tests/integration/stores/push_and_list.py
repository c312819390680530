#!/usr/bin/python3
"""A client in another language: pushes a model through the coordinator
(chunked PushArtifact, the inference service's, forwarded), lists it, and
checks that a corrupt model is refused naming the field and that nothing is
stored for it. Uses the Python code generated from proto/ at test time
(protoc with grpc_python_plugin) and Debian's python3-grpcio.

  push_and_list.py --gen DIR --server HOST:PORT --model FILE --id ID
Prints one JSON line; exit 0 when every check holds, 1 otherwise.
"""
import argparse
import json
import sys


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--gen", required=True)
    ap.add_argument("--server", required=True)
    ap.add_argument("--model", required=True)
    ap.add_argument("--id", required=True)
    args = ap.parse_args()
    sys.path.insert(0, args.gen)
    import grpc
    from kinemo.common.v1 import artifact_pb2
    from kinemo.inference.v1 import inference_pb2_grpc

    with open(args.model, "rb") as f:
        data = f.read()
    channel = grpc.insecure_channel(args.server)
    stub = inference_pb2_grpc.InferenceServiceStub(channel)

    def requests(model_id, payload, chunk=64 * 1024):
        header = artifact_pb2.PushArtifactHeader(
            ref=artifact_pb2.ArtifactRef(kind="models", id=model_id),
            description="pushed from Python",
            files=[artifact_pb2.ArtifactFile(name="model.kmodel", size_bytes=len(payload))])
        yield artifact_pb2.PushArtifactRequest(header=header)
        for off in range(0, len(payload), chunk):
            yield artifact_pb2.PushArtifactRequest(
                chunk=artifact_pb2.ArtifactChunk(file_index=0, offset=off, data=payload[off:off + chunk]))

    checks = {}
    pushed = stub.PushArtifact(requests(args.id, data), timeout=60)
    checks["pushed_id"] = pushed.artifact.ref.id == args.id and pushed.artifact.ref.version == 1
    listed = stub.ListArtifacts(artifact_pb2.ListArtifactsRequest(kind="models"), timeout=10)
    ids = [a.ref.id for a in listed.artifacts]
    checks["listed"] = ids == [args.id]
    checks["description"] = listed.artifacts[0].description == "pushed from Python" if listed.artifacts else False

    corrupt = bytes((i * 131 + 7) & 0xFF for i in range(len(data)))
    try:
        stub.PushArtifact(requests("corrupt", corrupt), timeout=60)
        checks["corrupt_refused"] = False
        error = ""
    except grpc.RpcError as e:
        error = e.details()
        checks["corrupt_refused"] = (e.code() == grpc.StatusCode.INVALID_ARGUMENT
                                     and error.startswith("header.files[0]: "))
    listed = stub.ListArtifacts(artifact_pb2.ListArtifactsRequest(kind="models"), timeout=10)
    checks["corrupt_not_stored"] = [a.ref.id for a in listed.artifacts] == [args.id]

    print(json.dumps({"checks": checks, "ids": ids, "corrupt_error": error}))
    return 0 if all(checks.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
