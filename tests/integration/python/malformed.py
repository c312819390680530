#!/usr/bin/python3
"""Malformed requests, sent raw from a client in another language (Debian's
python3-grpcio with the Python code generated from proto/ at test time), to
every unary and server-streaming RPC of the named services:
  - a string field holding invalid UTF-8  -> INVALID_ARGUMENT "<field>: invalid UTF-8"
  - a body that is not a message at all   -> INVALID_ARGUMENT "request: not a valid <type> message"
  - an enum field with an undefined number -> INVALID_ARGUMENT "<path>: 9999 is not a defined <Enum> value"
  - a NaN double field                    -> INVALID_ARGUMENT "<path>: not a finite number"
plus well-formed requests with values out of bounds (issue 26, SPECIFIC):
  - LoadLibrary meters_per_unit 1e308, segmentation.interruption_frames
    4294967295, two inline clips of one name -> INVALID_ARGUMENT naming the field
The bytes are built from each request's descriptor, so every RPC the proto
declares is covered without a list to keep in step.

  malformed.py --gen DIR --target LABEL HOST:PORT kinemo.x.v1.S,kinemo.y.v1.T [--target ...]
A target is a service's own address, or one that forwards to the services
listed (the coordinator, the all-in-one). Prints one JSON line;
exit 0 when every answer is as expected, 1 otherwise.
"""
import argparse
import importlib
import json
import base64
import struct
import sys

UNDEFINED_ENUM = 9999


def varint(n):
    out = bytearray()
    while True:
        b = n & 0x7F
        n >>= 7
        if n:
            out.append(b | 0x80)
        else:
            out.append(b)
            return bytes(out)


def tag(number, wire_type):
    return varint((number << 3) | wire_type)


def delimited(number, payload):
    return tag(number, 2) + varint(len(payload)) + payload


def nest(parents, leaf):
    """Wraps `leaf` (the encoded innermost field) in its singular message parents."""
    for number in reversed(parents):
        leaf = delimited(number, leaf)
    return leaf


def find_field(message_type, want, depth=0):
    """The first field (depth first, in field-number order) for which want(field)
    holds, through singular message fields: ([parent numbers], path, field)."""
    from google.protobuf.descriptor import FieldDescriptor as F
    fields = sorted(message_type.fields, key=lambda f: f.number)
    for f in fields:
        if want(f):
            return [], f.name + ("[0]" if f.label == F.LABEL_REPEATED else ""), f
    if depth >= 3:
        return None
    for f in fields:
        if f.type == F.TYPE_MESSAGE and f.label != F.LABEL_REPEATED and not f.message_type.GetOptions().map_entry:
            found = find_field(f.message_type, want, depth + 1)
            if found:
                parents, path, leaf = found
                return [f.number] + parents, f.name + "." + path, leaf
    return None


def cases_for(method):
    """(name, bytes, expected message prefix) for one method's request type."""
    from google.protobuf.descriptor import FieldDescriptor as F
    req = method.input_type
    cases = [("garbage", b"\xff\xff\xff", "request: not a valid %s message" % req.full_name)]
    found = find_field(req, lambda f: f.type == F.TYPE_STRING)
    if found:
        parents, path, f = found
        cases.append(("utf8", nest(parents, delimited(f.number, b"ok\xc3\x28")), path + ": invalid UTF-8"))
    found = find_field(req, lambda f: f.type == F.TYPE_ENUM)
    if found:
        parents, path, f = found
        cases.append(("enum", nest(parents, tag(f.number, 0) + varint(UNDEFINED_ENUM)),
                      "%s: %d is not a defined %s value" % (path, UNDEFINED_ENUM, f.enum_type.name)))
    found = find_field(req, lambda f: f.type == F.TYPE_DOUBLE)
    if found:
        parents, path, f = found
        cases.append(("nan", nest(parents, tag(f.number, 1) + struct.pack("<d", float("nan"))),
                      path + ": not a finite number"))
    return cases


# InlineClip.bvh is bytes: base64 in the JSON form.
HIERARCHY_B64 = base64.b64encode(b"HIERARCHY").decode("ascii")

# Well-formed requests that must be refused naming the field:
# service -> [(method, case, {field: value} of the request, expected prefix)].
SPECIFIC = {
    "kinemo.planner.v1.PlannerService": [
        ("LoadLibrary", "meters_per_unit_1e308",
         {"library_id": "malformed", "paths": ["none.bvh"], "meters_per_unit": 1e308}, "meters_per_unit:"),
        ("LoadLibrary", "interruption_frames_max",
         {"library_id": "malformed", "paths": ["none.bvh"], "segmentation": {"interruption_frames": 4294967295}},
         "segmentation.interruption_frames:"),
        ("LoadLibrary", "inline_clip_names_twice",
         {"library_id": "malformed", "clips": [{"name": "wave", "bvh": HIERARCHY_B64}, {"name": "wave", "bvh": HIERARCHY_B64}]},
         "clips[1].name:"),
    ],
}


def specific_cases(service):
    """(method, case, bytes, expected) of SPECIFIC for one service."""
    from google.protobuf import json_format, symbol_database
    out = []
    for method_name, case, fields, expected in SPECIFIC.get(service.full_name, []):
        method = service.methods_by_name[method_name]
        message = symbol_database.Default().GetSymbol(method.input_type.full_name)()
        json_format.ParseDict(fields, message, ignore_unknown_fields=False)
        out.append((method, case, message.SerializeToString(), expected))
    return out


def service_descriptor(full_name):
    from google.protobuf import descriptor_pool
    return descriptor_pool.Default().FindServiceByName(full_name)


def load_modules(gen):
    import os
    for root, _, files in os.walk(os.path.join(gen, "kinemo")):
        for f in files:
            if f.endswith("_pb2.py"):
                rel = os.path.relpath(os.path.join(root, f[:-3]), gen)
                importlib.import_module(rel.replace(os.sep, "."))


def main():
    ap = argparse.ArgumentParser()
    ap.add_argument("--gen", required=True)
    ap.add_argument("--target", nargs=3, action="append", required=True, metavar=("LABEL", "ADDRESS", "SERVICES"))
    args = ap.parse_args()
    sys.path.insert(0, args.gen)
    import grpc
    load_modules(args.gen)

    failures = []
    counts = {}
    for label, address, services in args.target:
        channel = grpc.insecure_channel(address)
        for service_name in services.split(","):
            service = service_descriptor(service_name)
            calls = []
            for method in service.methods:
                # Client streams are parsed message by message after the call
                # started; the request guard covers the calls gRPC parses first.
                if method.client_streaming:
                    continue
                calls += [(method, case, body, expected) for case, body, expected in cases_for(method)]
            calls += specific_cases(service)
            for method, case, body, expected in calls:
                path = "/%s/%s" % (service.full_name, method.name)
                if method.server_streaming:
                    call = channel.unary_stream(path)
                else:
                    call = channel.unary_unary(path)
                try:
                    result = call(body, timeout=20)
                    if method.server_streaming:
                        for _ in result:
                            pass
                    got = ("OK", "")
                except grpc.RpcError as e:
                    got = (e.code().name, e.details() or "")
                counts[label] = counts.get(label, 0) + 1
                if got[0] != "INVALID_ARGUMENT" or not got[1].startswith(expected):
                    failures.append({"server": label, "method": path, "case": case, "expected": expected,
                                     "code": got[0], "message": got[1]})
        channel.close()
    print(json.dumps({"calls": counts, "failures": failures}))
    return 0 if not failures and counts else 1


if __name__ == "__main__":
    sys.exit(main())
