// gRPC adapter of the planner (callback API): the motion library here, and
// each area's RPCs in a file of their own in this folder (rpc/); the areas'
// cores (../controller, ../gesture, ../locomotion, ../rig) have no gRPC:
//   controller_rpcs.cc  BuildController, Synthesize(Chunked), Control
//   gesture_rpcs.cc     BuildGestureGraph, SynthesizeGestures(Chunked), Visemes(Chunked)
//   locomotion_rpcs.cc  BuildLocomotionGraph, PlanTransition,
//                       EvaluateLocomotion, Drive
//   rig_rpcs.cc         the "rigs" artifact kind, a library's motion on a rig
//   artifact_rpcs.cc    PushArtifact, ListArtifacts, DeleteArtifact,
//                       and the artifact store's loading at start
// Everything built, loaded or pushed is an artifact version in the store
// (PlannerOptions.store_dir, or a temporary folder removed at exit): the
// objects served are the newest version of each id and carry its number.
// RPCs not overridden answer UNIMPLEMENTED. Core errors become grpc::Status
// only through ToGrpcStatus.
#pragma once

#include <functional>
#include <memory>
#include <mutex>
#include <optional>
#include <string>
#include <vector>

#include <grpcpp/grpcpp.h>

#include "common/grpc/artifact_rpcs.h"
#include "common/grpc/worker_write_reactor.h"
#include "common/status/cancel.h"
#include "common/status/status.h"
#include "common/motion/bvh.h"
#include "common/store/artifact_store.h"
#include "kinemo/planner/v1/options.pb.h"
#include "kinemo/planner/v1/planner.grpc.pb.h"
#include "services/planner/library/library.h"
// ---- Gesture Controller (controller_rpcs.cc)
#include <atomic>

#include "services/planner/controller/controller.h"
// gesture (GMG/BodySpeech)
#include "services/planner/gesture/graph.h"
#include "services/planner/gesture/synthesis.h"
#include "services/planner/gesture/visemes.h"
// rigs
#include "services/planner/rig/rig_motion.h"

namespace kinemo::planner {

// A call's motion, ready to send: the clip and how its skeleton is described.
struct MotionOut {
  motion::Clip clip;
  double meters_per_unit = 0;
  motion::BodyRegionMap regions;
  std::string skeleton_name;
  std::string clip_name;
  motion::BvhWriteOptions bvh;
};

// A call's motion as MotionChunk pieces of at most 1 MiB, made one at a time
// (the chunked RPCs): BVH text (BvhTextWriter), or a header and frame
// batches.
class MotionChunker {
 public:
  // Errors as MotionToProto.
  static StatusOr<std::unique_ptr<MotionChunker>> Create(MotionOut motion, common::v1::MotionFormat format);
  // The next piece into `out`; false once every piece was made.
  bool Next(common::v1::MotionChunk* out);
  int frames() const { return motion_.clip.num_frames(); }

 private:
  explicit MotionChunker(MotionOut motion) : motion_(std::move(motion)) {}
  MotionOut motion_;
  bool clip_format_ = false;
  std::optional<motion::BvhTextWriter> bvh_;
  bool header_sent_ = false;
  int next_frame_ = 0;
};

// The longest output of the chunked RPCs (PlannerOptions.max_chunked_output_s, 0 = 7200 s).
inline double MaxChunkedOutputS(const v1::PlannerOptions& o) {
  return o.max_chunked_output_s() > 0 ? o.max_chunked_output_s() : 7200;
}
// Pieces a chunked RPC queues ahead of the client (about 4 MiB).
inline constexpr std::size_t kChunkedQueue = 4;
// The chunked calls running at once (PlannerOptions.max_concurrent_chunked, 0 = 2).
inline int MaxConcurrentChunked(const v1::PlannerOptions& o) {
  return o.max_concurrent_chunked() > 0 ? static_cast<int>(o.max_concurrent_chunked()) : 2;
}

class PlannerServiceImpl final : public v1::PlannerService::CallbackService {
 public:
  // Opens the store (imports seed_store_dir, loads every artifact; one that
  // fails to load is logged and skipped), then runs the preloads whose ids the
  // store does not hold.
  static StatusOr<std::shared_ptr<PlannerServiceImpl>> Create(const v1::PlannerOptions& options);
  ~PlannerServiceImpl() override;

  // ---- Motion library (planner_service.cc)
  grpc::ServerUnaryReactor* LoadLibrary(grpc::CallbackServerContext* ctx, const v1::LoadLibraryRequest* request,
                                        v1::LoadLibraryResponse* response) override;

  // ---- Locomotion: Body Part Motion Graphs, AvatAR (locomotion_rpcs.cc)
  grpc::ServerUnaryReactor* BuildLocomotionGraph(grpc::CallbackServerContext* ctx,
                                                 const v1::BuildLocomotionGraphRequest* request,
                                                 v1::BuildLocomotionGraphResponse* response) override;
  grpc::ServerUnaryReactor* PlanTransition(grpc::CallbackServerContext* ctx, const v1::PlanTransitionRequest* request,
                                           v1::PlanTransitionResponse* response) override;
  grpc::ServerUnaryReactor* EvaluateLocomotion(grpc::CallbackServerContext* ctx,
                                               const v1::EvaluateLocomotionRequest* request,
                                               v1::EvaluateLocomotionResponse* response) override;
  grpc::ServerBidiReactor<v1::DriveRequest, v1::DriveResponse>* Drive(grpc::CallbackServerContext* ctx) override;
  struct LocomotionState;  // graphs, feature cache, build and stream counters
  static std::shared_ptr<LocomotionState> MakeLocomotionState();
  // ---- end locomotion
  // ---- Gesture Controller (controller_rpcs.cc)
  grpc::ServerWriteReactor<v1::BuildControllerResponse>* BuildController(
      grpc::CallbackServerContext* ctx, const v1::BuildControllerRequest* request) override;
  grpc::ServerUnaryReactor* Synthesize(grpc::CallbackServerContext* ctx, const v1::SynthesizeRequest* request,
                                       v1::SynthesizeResponse* response) override;
  grpc::ServerBidiReactor<v1::ControlRequest, v1::ControlResponse>* Control(grpc::CallbackServerContext* ctx) override;
  grpc::ServerWriteReactor<v1::SynthesizeChunkedResponse>* SynthesizeChunked(
      grpc::CallbackServerContext* ctx, const v1::SynthesizeRequest* request) override;
  struct StoredController {
    int version = 0;
    std::shared_ptr<const controller::Controller> controller;
    v1::ControllerInfo info;
  };
  VersionedStore<StoredController>& controllers() { return controllers_; }
  std::atomic<int> controller_builds{0};
  std::atomic<int> control_streams{0};
  std::atomic<int> chunked_calls{0};  // SynthesizeChunked, SynthesizeGesturesChunked, VisemesChunked
  // Synthesize's work, for the unary and the chunked RPC: the motion (on the
  // request's rig when it names one) and the segments played. Output up to
  // `max_output_s`.
  struct ControllerSynthesis {
    MotionOut motion;
    controller::SynthesisResult result;  // its clip moved into `motion`
    std::shared_ptr<const StoredController> stored;
  };
  StatusOr<ControllerSynthesis> RunSynthesize(const v1::SynthesizeRequest& request, double max_output_s,
                                              const CancelToken* cancel);
  // ---- end Gesture Controller
  // ---- Gesture Motion Graph and BodySpeech (gesture_rpcs.cc)
  grpc::ServerUnaryReactor* BuildGestureGraph(grpc::CallbackServerContext* ctx,
                                              const v1::BuildGestureGraphRequest* request,
                                              v1::BuildGestureGraphResponse* response) override;
  grpc::ServerUnaryReactor* SynthesizeGestures(grpc::CallbackServerContext* ctx,
                                               const v1::SynthesizeGesturesRequest* request,
                                               v1::SynthesizeGesturesResponse* response) override;
  grpc::ServerUnaryReactor* Visemes(grpc::CallbackServerContext* ctx, const v1::VisemesRequest* request,
                                    v1::VisemesResponse* response) override;
  grpc::ServerWriteReactor<v1::SynthesizeGesturesChunkedResponse>* SynthesizeGesturesChunked(
      grpc::CallbackServerContext* ctx, const v1::SynthesizeGesturesRequest* request) override;
  grpc::ServerWriteReactor<v1::VisemesResponse>* VisemesChunked(grpc::CallbackServerContext* ctx,
                                                                const v1::VisemesRequest* request) override;
  // SynthesizeGestures' work, for the unary and the chunked RPC: the motion
  // (on the request's rig when it names one), the report and (with
  // include_visemes) the visemes. Output up to `max_output_s`.
  struct GestureSynthesis {
    MotionOut motion;
    gesture::SynthesisResult result;  // its clip moved into `motion`
    gesture::VisemeTrack visemes;
  };
  StatusOr<GestureSynthesis> RunSynthesizeGestures(const v1::SynthesizeGesturesRequest& request, double max_output_s,
                                                   const CancelToken* cancel);
  // BuildGestureGraph without the RPC (also used by PlannerOptions.preload_gesture_graphs).
  Status BuildAndStoreGestureGraph(const v1::BuildGestureGraphRequest* request,
                                   v1::BuildGestureGraphResponse* response);
  // ---- end gesture
  // ---- Rigs: users' characters, motion retargeted onto them (rig_rpcs.cc)
  VersionedStore<rig::StoredRig>& rigs() { return rigs_; }
  // The motion of `library` on the rig `rig_id` names (a new retargeter for
  // one call or stream), or null when rig_id is empty. NOT_FOUND naming
  // `field` for an id no rig is stored under.
  StatusOr<std::unique_ptr<rig::RigMotion>> MotionOnRig(const std::string& rig_id, const Library& library,
                                                        double frame_time_s, std::string_view field);
  // ---- end rigs

  // ---- Artifacts (artifact_rpcs.cc)
  grpc::ServerReadReactor<common::v1::PushArtifactRequest>* PushArtifact(
      grpc::CallbackServerContext* ctx, common::v1::PushArtifactResponse* response) override;
  grpc::ServerUnaryReactor* ListArtifacts(grpc::CallbackServerContext* ctx,
                                          const common::v1::ListArtifactsRequest* request,
                                          common::v1::ListArtifactsResponse* response) override;
  grpc::ServerUnaryReactor* DeleteArtifact(grpc::CallbackServerContext* ctx,
                                           const common::v1::DeleteArtifactRequest* request,
                                           common::v1::DeleteArtifactResponse* response) override;
  // What the service does with one kind of artifact; each area supplies its
  // own (LibraryKind here, ControllerKind, GestureGraphKind,
  // LocomotionGraphKind in the areas' files).
  struct ArtifactKind {
    std::string kind;
    // The version of `id` served, 0 if none.
    std::function<int(const std::string& id)> served_version;
    // Reads a stored version and serves it in place of what `id` served.
    std::function<Status(const store::ArtifactMeta& meta)> serve;
    // Stops serving `id`.
    std::function<void(const std::string& id)> unserve;
    // PushArtifact of this kind: validates the draft (by loading or building
    // what it holds), commits it and serves it.
    std::function<StatusOr<common::v1::PushArtifactResponse>(store::Draft draft,
                                                             const common::v1::PushArtifactHeader& header)>
        push;
  };
  ArtifactKind LibraryKind();
  ArtifactKind ControllerKind();
  ArtifactKind GestureGraphKind();
  ArtifactKind LocomotionGraphKind();
  ArtifactKind RigKind();  // rig_rpcs.cc

  store::ArtifactStore& store() { return *store_; }
  // ALREADY_EXISTS naming `field` when `kind` holds `id` and !overwrite.
  Status CheckNewVersion(std::string_view kind, const std::string& id, bool overwrite, std::string_view field) const;
  // Commits `draft` as the next version of its id (ALREADY_EXISTS naming
  // `field` when it exists and !overwrite; FAILED_PRECONDITION when an
  // artifact in meta.depends_on is no longer stored), then calls
  // install(version) to serve it, while no other commit or delete runs.
  StatusOr<store::ArtifactMeta> CommitArtifact(store::Draft draft, store::ArtifactMeta meta, bool overwrite,
                                               std::string_view field, const std::function<void(int)>& install);
  // The stored library `id` at `version` (0 = the newest stored): the one
  // served when it is that version, else read from the store. NOT_FOUND
  // naming `field`.
  StatusOr<std::shared_ptr<const Library>> StoredLibrary(const std::string& id, std::uint32_t version,
                                                         std::string_view field);
  // The library an artifact version depends on (its depends_on entry of kind
  // "libraries"). FAILED_PRECONDITION when there is none or it is not stored.
  StatusOr<std::shared_ptr<const Library>> DependencyLibrary(const store::ArtifactMeta& meta);
  // The contents of a file of a stored version or a draft (text protos,
  // manifests), at most 16 MiB; errors name `field`.
  static StatusOr<std::string> ReadArtifactFile(const std::string& path, std::string_view field);
  // Graphs are stored as their build request (a Build*GraphRequest with its
  // parameters resolved), kGraphRecipeFile, depending on the library version.
  // A draft of kind/id holding `recipe`, and its metadata in `meta`.
  StatusOr<store::Draft> WriteRecipe(std::string_view kind, const std::string& id,
                                     const google::protobuf::Message& recipe, const Library& library,
                                     std::string description, std::string summary_json, store::ArtifactMeta* meta);
  // A stored recipe parsed into `recipe`, and the library it is built on.
  StatusOr<std::shared_ptr<const Library>> ReadStoredRecipe(const store::ArtifactMeta& meta,
                                                            google::protobuf::Message* recipe);
  // A pushed recipe (header.files: one kGraphRecipeFile) parsed into `recipe`,
  // and the library to build it on: the header's depends_on library, else
  // the recipe's library_id (newest version). Checks that the id is new
  // unless header.overwrite.
  StatusOr<std::shared_ptr<const Library>> ReadPushedRecipe(const store::Draft& draft,
                                                            const common::v1::PushArtifactHeader& header,
                                                            google::protobuf::Message* recipe);

  // Shared by the areas.
  const v1::PlannerOptions& options() const { return options_; }
  LibraryStore& libraries() { return libraries_; }
  // Resolves a server-side path under options.library_root; FAILED_PRECONDITION
  // (naming `field`) when it is outside or no root is configured.
  StatusOr<std::string> ResolvePath(const std::string& relative, std::string_view field) const;
  // Loads a library from a request, stores it as the next version of its id
  // and serves it; used by LoadLibrary and preload.
  StatusOr<std::shared_ptr<const Library>> LoadAndStore(const v1::LoadLibraryRequest& request,
                                                        std::vector<std::string>* warnings);
  gesture::GestureGraphStore& gesture_graphs() { return gesture_graphs_; }

 private:
  explicit PlannerServiceImpl(v1::PlannerOptions options) : options_(std::move(options)) {}
  // Opens store_dir (or a temporary store), imports the seed and serves every
  // stored artifact (artifact_rpcs.cc).
  Status OpenStore();
  const ArtifactKind* FindKind(std::string_view kind) const;
  // Writes a loaded library (files of `sources`) as the next version of its
  // id and serves it.
  StatusOr<store::ArtifactMeta> StoreLibrary(std::shared_ptr<Library> library, const LibrarySources& sources,
                                             std::string description, bool overwrite, std::string_view field);
  StatusOr<common::v1::PushArtifactResponse> PushLibrary(store::Draft draft,
                                                         const common::v1::PushArtifactHeader& header);
  // A stored library version read from the store (not served).
  StatusOr<std::shared_ptr<Library>> ReadStoredLibrary(const store::ArtifactMeta& meta) const;
  v1::PlannerOptions options_;
  std::unique_ptr<store::ArtifactStore> store_;
  std::string temporary_store_dir_;  // removed at destruction; empty with store_dir
  std::vector<ArtifactKind> kinds_;  // in dependency order: libraries first
  std::mutex store_mu_;              // commits + serving, deletes + unserving
  std::shared_ptr<const ArtifactPushHandler> push_handler_;
  LibraryStore libraries_;
  // Locomotion (locomotion_rpcs.cc).
  std::shared_ptr<LocomotionState> locomotion_ = MakeLocomotionState();
  VersionedStore<StoredController> controllers_;  // Gesture Controller
  // gesture: stored Gesture Motion Graphs.
  gesture::GestureGraphStore gesture_graphs_;
  VersionedStore<rig::StoredRig> rigs_;  // rigs
};

// Finishes a unary call with `status` (mapped by ToGrpcStatus).
grpc::ServerUnaryReactor* FinishUnary(grpc::CallbackServerContext* ctx, const Status& status);

// A skeleton as the API sends it (regions per joint when known).
void SkeletonToProto(const motion::Skeleton& skeleton, double meters_per_unit, const motion::BodyRegionMap& regions,
                     std::string_view name, common::v1::Skeleton* out);
// A clip with that skeleton and its frames.
void ClipToProto(const motion::Clip& clip, double meters_per_unit, const motion::BodyRegionMap& regions,
                 std::string_view name, common::v1::MotionClip* out);

// A call's motion in the requested form (a clip named `clip_name` on a
// skeleton named `skeleton_name`, or BVH).
Status MotionToProto(const motion::Clip& clip, double meters_per_unit, const motion::BodyRegionMap& regions,
                     std::string_view skeleton_name, std::string_view clip_name, common::v1::MotionFormat format, const motion::BvhWriteOptions& bvh,
                     common::v1::Motion* out);

// Library description for responses.
void ToProto(const Library& library, v1::LibraryInfo* out);

inline constexpr std::string_view kGraphRecipeFile = "graph.textproto";

// A proto message as JSON (proto field names), for artifact summaries.
std::string SummaryJson(const google::protobuf::Message& message);

// An error from validating a pushed draft: the draft's folder removed from
// the message (so that it names the file as pushed) and `field` prepended.
Status PushError(const Status& status, const store::Draft& draft, std::string_view field);

// The depends_on entry of kind "libraries" of a pushed recipe or controller
// (its index, -1 when there is none); INVALID_ARGUMENT when there are
// several.
StatusOr<int> LibraryDependency(const common::v1::PushArtifactHeader& header);

// A chunked RPC (SynthesizeChunked, SynthesizeGesturesChunked,
// VisemesChunked): `work` on a worker thread once one of
// max_concurrent_chunked is free, its pieces sent as the client reads them
// (kChunkedQueue ahead).
template <typename Response>
grpc::ServerWriteReactor<Response>* NewChunkedCall(
    PlannerServiceImpl* svc, std::function<Status(const typename SlotWorkerReactor<Response>::Sender&)> work) {
  return new SlotWorkerReactor<Response>(&svc->chunked_calls, MaxConcurrentChunked(svc->options()),
                                         "max_concurrent_chunked", "chunked syntheses", kChunkedQueue,
                                         std::move(work));
}

// The motion as MotionChunker pieces, each in a Response's `motion`;
// CANCELLED once the client went away.
template <typename Response>
Status SendMotionPieces(MotionOut motion, common::v1::MotionFormat format,
                        const std::function<bool(Response)>& send) {
  KINEMO_ASSIGN_OR_RETURN(std::unique_ptr<MotionChunker> chunks, MotionChunker::Create(std::move(motion), format));
  while (true) {
    Response piece;
    if (!chunks->Next(piece.mutable_motion())) return absl::OkStatus();
    if (!send(std::move(piece))) return absl::CancelledError("the client went away");
  }
}

}  // namespace kinemo::planner
