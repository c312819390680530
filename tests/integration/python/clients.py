#!/usr/bin/python3
"""One real call per kinemo service from a client in another language
(Debian's python3-grpcio, code generated from proto/ at test time):

  prosody       Analyze on a real speech recording
  inference     PushArtifact (a model file) then Infer on prosody features
  planner       Visemes on timed phones; LoadLibrary with a missing path
                (NOT_FOUND, with no server path in the message)
  cube_tracker  Track on rendered frames of the real cube model
  robot_bridge  SetEmotion(wait_applied) against pleo_sim
  coordinator   OpenSession + Act + CloseSession

  clients.py --gen DIR --prosody A --inference A --planner A --cube-tracker A
             --robot-bridge A --coordinator A --speech WAV --model FILE
             --frames PNG[,PNG...] --top-face N --hide PATH
Prints one JSON line {"checks": {...}, ...}; exit 0 when every check holds.
"""
import argparse
import json
import sys


def main():
    ap = argparse.ArgumentParser()
    for name in ("gen", "prosody", "inference", "planner", "cube-tracker", "robot-bridge", "coordinator", "speech",
                 "model", "frames", "hide"):
        ap.add_argument("--" + name, required=True)
    ap.add_argument("--top-face", type=int, required=True)
    args = ap.parse_args()
    sys.path.insert(0, args.gen)
    import grpc
    from kinemo.common.v1 import artifact_pb2, audio_pb2, speech_pb2, vleo_pb2
    from kinemo.coordinator.v1 import coordinator_pb2, coordinator_pb2_grpc
    from kinemo.cube_tracker.v1 import cube_tracker_pb2, cube_tracker_pb2_grpc
    from kinemo.inference.v1 import inference_pb2, inference_pb2_grpc
    from kinemo.planner.v1 import planner_pb2, planner_pb2_grpc
    from kinemo.prosody.v1 import prosody_pb2, prosody_pb2_grpc
    from kinemo.robot_bridge.v1 import robot_bridge_pb2, robot_bridge_pb2_grpc

    checks = {}
    info = {}

    # prosody: Analyze a real recording.
    prosody = prosody_pb2_grpc.ProsodyServiceStub(grpc.insecure_channel(args.prosody))
    with open(args.speech, "rb") as f:
        audio = audio_pb2.Audio(format=audio_pb2.AudioFormat(encoding=audio_pb2.AUDIO_ENCODING_FILE), data=f.read())
    track = prosody.Analyze(prosody_pb2.AnalyzeRequest(audio=audio), timeout=120).track
    info["syllables"] = len(track.syllables)
    checks["prosody_syllables"] = len(track.syllables) >= 5 and len(track.accents) >= 1

    # inference: push a model, then Infer on the syllables just found.
    inference = inference_pb2_grpc.InferenceServiceStub(grpc.insecure_channel(args.inference))
    with open(args.model, "rb") as f:
        model = f.read()

    def push():
        yield artifact_pb2.PushArtifactRequest(header=artifact_pb2.PushArtifactHeader(
            ref=artifact_pb2.ArtifactRef(kind="models", id="py"),
            files=[artifact_pb2.ArtifactFile(name="model.kmodel", size_bytes=len(model))]))
        yield artifact_pb2.PushArtifactRequest(chunk=artifact_pb2.ArtifactChunk(file_index=0, offset=0, data=model))

    inference.PushArtifact(push(), timeout=60)
    inputs = [inference_pb2.ProsodyFeatures(start_s=s.start_s, end_s=s.end_s, f0_mean_hz=s.f0_mean_hz,
                                            intensity_mean_db=s.intensity_mean_db, length_s=s.length_s,
                                            voiced=s.voiced) for s in track.syllables]
    inferred = inference.Infer(inference_pb2.InferRequest(model_id="py", inputs=inputs), timeout=60)
    sums = [sum(b.probabilities) for b in inferred.smoothed]
    checks["inference_beliefs"] = (len(inferred.smoothed) == len(inputs)
                                   and all(abs(s - 1.0) < 1e-6 for s in sums))

    # planner: visemes for timed phones.
    planner = planner_pb2_grpc.PlannerServiceStub(grpc.insecure_channel(args.planner))
    phones = [speech_pb2.Phone(phone=p, start_s=0.1 * i, end_s=0.1 * (i + 1))
              for i, p in enumerate(["HH", "EH", "L", "OW"])]
    visemes = planner.Visemes(planner_pb2.VisemesRequest(phones=phones), timeout=30)
    checks["planner_visemes"] = len(visemes.track.frames) > 0 and not visemes.unknown_phones
    try:
        planner.LoadLibrary(planner_pb2.LoadLibraryRequest(library_id="nothing", paths=["missing.bvh"]), timeout=30)
        checks["planner_missing_path"] = False
    except grpc.RpcError as e:
        info["missing_path_error"] = e.details()
        checks["planner_missing_path"] = (e.code() == grpc.StatusCode.NOT_FOUND and "missing.bvh" in e.details()
                                          and args.hide not in e.details())

    # cube_tracker: Track on real frames (the server's default cube and camera).
    cube = cube_tracker_pb2_grpc.CubeTrackerServiceStub(grpc.insecure_channel(args.cube_tracker))
    frames = args.frames.split(",")

    def track_requests():
        yield cube_tracker_pb2.TrackRequest(config=cube_tracker_pb2.TrackConfig())
        for i, path in enumerate(frames):
            with open(path, "rb") as f:
                image = cube_tracker_pb2.Image(encoding=cube_tracker_pb2.IMAGE_ENCODING_PNG, data=f.read())
            yield cube_tracker_pb2.TrackRequest(frame=cube_tracker_pb2.TrackFrame(frame=i, time_s=i / 30.0,
                                                                                   image=image))

    states = [r.state for r in cube.Track(track_requests(), timeout=60) if r.HasField("state")]
    info["top_faces"] = [s.top_face for s in states]
    checks["cube_top_face"] = (len(states) == len(frames) and states[-1].visible
                               and states[-1].top_face == args.top_face)

    # robot_bridge: Pleo shows HAPPY once pleo_sim applied it.
    bridge = robot_bridge_pb2_grpc.RobotBridgeServiceStub(grpc.insecure_channel(args.robot_bridge))
    applied = bridge.SetEmotion(robot_bridge_pb2.SetEmotionRequest(robot_id="pleo", emotion=vleo_pb2.EMOTION_HAPPY,
                                                                   intensity=1.0, wait_applied=True), timeout=30)
    status = bridge.GetStatus(robot_bridge_pb2.GetStatusRequest(robot_id="pleo"), timeout=10)
    checks["robot_happy"] = applied.applied and status.shown_emotion == vleo_pb2.EMOTION_HAPPY

    # coordinator: a session, a kiss, closed.
    coordinator = coordinator_pb2_grpc.CoordinatorServiceStub(grpc.insecure_channel(args.coordinator))
    opened = coordinator.OpenSession(coordinator_pb2.OpenSessionRequest(session_id="py", robot_id="pleo"), timeout=10)
    acted = coordinator.Act(coordinator_pb2.ActRequest(session_id="py", action=vleo_pb2.ACTION_KISSES,
                                                       intensity=1.0), timeout=10)
    coordinator.CloseSession(coordinator_pb2.CloseSessionRequest(session_id="py"), timeout=10)
    checks["coordinator_session"] = opened.session.session_id == "py" and acted.session.session_id == "py"

    print(json.dumps({"checks": checks, "info": info}))
    return 0 if all(checks.values()) else 1


if __name__ == "__main__":
    sys.exit(main())
