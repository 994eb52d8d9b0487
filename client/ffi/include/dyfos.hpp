// dyfos.hpp: header-only C++17 wrapper of the dyfos C API (dyfos.h, libdyfos).
//
//   dyfos::Client client("dyfos/");                       // RAII: closed when it goes out of scope
//   auto [map, version] = client.upload_scenario(json);    // a SPEC §11 scenario's map
//   dyfos::RendezvousRequest request = dyfos::RendezvousRequest::from_scenario(json, map);
//   request.seed = 7;
//   dyfos::Answer answer = client.rendezvous(request);     // throws dyfos::Error on failure
//   std::cout << answer.to_json() << "\n";                 // what `dyfos solve --seed 7` prints
//
// Errors are exceptions derived from dyfos::Error (status() is the dyfos_status code,
// name() its snake_case name, what() the message): UnknownMapError,
// VersionMismatchError, InvalidRequestError, NoFeasiblePoseError,
// DeadlineExceededError, OverCapacityError, BusyError, DaemonGoneError,
// TimeoutError. A Client is move-only; its calls may come from several threads (the
// library serialises them). dyfos.h's rules (threads, signals, ownership) hold here.
// Compiles clean with -Wall -Wextra -Wconversion -Wsign-conversion.
#ifndef DYFOS_HPP
#define DYFOS_HPP

#include "dyfos.h"

#include <array>
#include <chrono>
#include <cstdint>
#include <optional>
#include <stdexcept>
#include <string>
#include <utility>
#include <vector>

namespace dyfos {

/// The families of errors a caller handles differently.
enum class ErrorKind {
  UnknownMap,       ///< no map has this id (DYFOS_STATUS_UNKNOWN_MAP)
  VersionMismatch,  ///< the map is not at the expected version
  InvalidRequest,   ///< malformed or invalid request, belief, params, deltas, arguments; map exists; chunks
  NoFeasiblePose,   ///< no candidate pose passed the constraints
  DeadlineExceeded, ///< the deadline passed before any feasible pose was found
  OverCapacity,     ///< too large for the daemon's limits: send less or make room; a retry cannot help
  Busy,             ///< busy or shutting down: retry later
  DaemonGone,       ///< no daemon, or it went away mid-request: retry (the client reconnects)
  Timeout,          ///< no reply within the call's timeout
  Other,            ///< storage failed, internal error, ipc, incompatible daemon, panic
};

/// The family of a status code.
inline ErrorKind error_kind(dyfos_status status) noexcept {
  switch (status) {
    case DYFOS_STATUS_UNKNOWN_MAP: return ErrorKind::UnknownMap;
    case DYFOS_STATUS_MAP_VERSION_MISMATCH: return ErrorKind::VersionMismatch;
    case DYFOS_STATUS_MALFORMED_REQUEST:
    case DYFOS_STATUS_INVALID_ALGORITHM:
    case DYFOS_STATUS_INVALID_BELIEF:
    case DYFOS_STATUS_INVALID_PARAMS:
    case DYFOS_STATUS_UNSUPPORTED_MODEL:
    case DYFOS_STATUS_INVALID_DEADLINE:
    case DYFOS_STATUS_MALFORMED_DELTA:
    case DYFOS_STATUS_INVALID_DELTA:
    case DYFOS_STATUS_MAP_EXISTS:
    case DYFOS_STATUS_CHUNK_OUT_OF_ORDER:
    case DYFOS_STATUS_CHUNK_DUPLICATE:
    case DYFOS_STATUS_CHUNK_INCOMPLETE:
    case DYFOS_STATUS_NULL_PARAMETER:
    case DYFOS_STATUS_INVALID_ARGUMENT: return ErrorKind::InvalidRequest;
    case DYFOS_STATUS_NO_FEASIBLE_POSE: return ErrorKind::NoFeasiblePose;
    case DYFOS_STATUS_DEADLINE_EXCEEDED: return ErrorKind::DeadlineExceeded;
    case DYFOS_STATUS_OVER_CAPACITY: return ErrorKind::OverCapacity;
    case DYFOS_STATUS_BUSY:
    case DYFOS_STATUS_SHUTTING_DOWN: return ErrorKind::Busy;
    case DYFOS_STATUS_NO_DAEMON:
    case DYFOS_STATUS_DAEMON_GONE: return ErrorKind::DaemonGone;
    case DYFOS_STATUS_TIMEOUT: return ErrorKind::Timeout;
    default: return ErrorKind::Other;
  }
}

/// A failed call: the status code, its name and the library's (or daemon's) message.
class Error : public std::runtime_error {
 public:
  Error(dyfos_status status, const std::string& message)
      : std::runtime_error(message), status_(status) {}
  /// The dyfos_status code (DYFOS_STATUS_*).
  dyfos_status status() const noexcept { return status_; }
  /// Its snake_case name, e.g. "map_version_mismatch".
  const char* name() const noexcept { return dyfos_status_name(status_); }
  /// Its family.
  ErrorKind kind() const noexcept { return error_kind(status_); }

 private:
  dyfos_status status_;
};

/// DYFOS_STATUS_UNKNOWN_MAP: upload or create the map first.
struct UnknownMapError : Error { using Error::Error; };
/// DYFOS_STATUS_MAP_VERSION_MISMATCH: re-read the map (snapshot) and retry.
struct VersionMismatchError : Error { using Error::Error; };
/// The request cannot succeed as it is: fix what the message names.
struct InvalidRequestError : Error { using Error::Error; };
/// DYFOS_STATUS_NO_FEASIBLE_POSE.
struct NoFeasiblePoseError : Error { using Error::Error; };
/// DYFOS_STATUS_DEADLINE_EXCEEDED: give more time, or accept no answer.
struct DeadlineExceededError : Error { using Error::Error; };
/// DYFOS_STATUS_OVER_CAPACITY: too many records (a batch over DYFOS_MAX_BATCH_RECORDS,
/// inline deltas over DYFOS_MAX_INLINE_RECORDS), maps, uploads, obstacles or cells.
/// Sending the same again cannot help: split the batch, or delete maps.
struct OverCapacityError : Error { using Error::Error; };
/// Busy or shutting down: retry later.
struct BusyError : Error { using Error::Error; };
/// No daemon, or it went away mid-request: retry; the client reconnects by itself.
struct DaemonGoneError : Error { using Error::Error; };
/// No reply within the call's timeout.
struct TimeoutError : Error { using Error::Error; };

namespace detail {

/// This thread's last error message.
inline std::string last_error() {
  std::string message(dyfos_last_error(nullptr, 0), '\0');
  if (!message.empty()) {
    std::string buffer(message.size() + 1, '\0');
    dyfos_last_error(buffer.data(), buffer.size());
    message.assign(buffer.c_str());
  }
  return message;
}

/// Throws the exception of `status`'s family unless it is OK.
inline void check(dyfos_status status) {
  if (status == DYFOS_STATUS_OK) return;
  std::string message = last_error();
  switch (error_kind(status)) {
    case ErrorKind::UnknownMap: throw UnknownMapError(status, message);
    case ErrorKind::VersionMismatch: throw VersionMismatchError(status, message);
    case ErrorKind::InvalidRequest: throw InvalidRequestError(status, message);
    case ErrorKind::NoFeasiblePose: throw NoFeasiblePoseError(status, message);
    case ErrorKind::DeadlineExceeded: throw DeadlineExceededError(status, message);
    case ErrorKind::OverCapacity: throw OverCapacityError(status, message);
    case ErrorKind::Busy: throw BusyError(status, message);
    case ErrorKind::DaemonGone: throw DaemonGoneError(status, message);
    case ErrorKind::Timeout: throw TimeoutError(status, message);
    default: throw Error(status, message);
  }
}

/// Takes ownership of a string the library returned.
inline std::string take(char* s) {
  std::string out = s ? std::string(s) : std::string();
  dyfos_string_free(s);
  return out;
}

/// A call's timeout for the C API: none = 0 (the client's); not positive throws.
inline std::uint64_t timeout_ms(const std::optional<std::chrono::milliseconds>& timeout) {
  if (!timeout) return 0;
  if (timeout->count() <= 0) {
    throw InvalidRequestError(DYFOS_STATUS_INVALID_ARGUMENT,
                              "timeout = " + std::to_string(timeout->count()) +
                                  " ms: give a positive timeout, or none for the client's");
  }
  return static_cast<std::uint64_t>(timeout->count());
}

}  // namespace detail

/// The search algorithms (SPEC §8).
enum class Algorithm : std::uint32_t {
  Dyfos = DYFOS_ALGORITHM_DYFOS,
  DyfosScipy = DYFOS_ALGORITHM_DYFOS_SCIPY,
  Brute = DYFOS_ALGORITHM_BRUTE,
  Random = DYFOS_ALGORITHM_RANDOM,
  Center = DYFOS_ALGORITHM_CENTER,
};

/// The SDSMM noise models.
enum class Model : std::uint32_t {
  Paper = DYFOS_MODEL_PAPER,
  Anisotropic = DYFOS_MODEL_ANISOTROPIC,
  Learned = DYFOS_MODEL_LEARNED,
};

/// Parameters (SPEC §11): everything not set is the SPEC default. Each setter
/// sets the field's bit, e.g. `dyfos::Params().lambda(2.0).model(dyfos::Model::Anisotropic)`;
/// each getter gives the value a request uses: the field if its bit is set, else
/// the default.
class Params {
 public:
  Params() : raw_(defaults()) {}
  /// From a JSON object of SPEC §11 names; throws InvalidRequestError naming a bad
  /// field (DYFOS_STATUS_INVALID_ARGUMENT for an unknown one, DYFOS_STATUS_INVALID_PARAMS
  /// for a value out of range).
  static Params from_json(const std::string& json) {
    Params p;
    detail::check(dyfos_params_from_json(json.c_str(), &p.raw_));
    return p;
  }
#define DYFOS_HPP_FIELD(name, type, bit)                                    \
  Params& name(type v) noexcept {                                          \
    raw_.name = v;                                                         \
    raw_.set |= bit;                                                       \
    return *this;                                                          \
  }                                                                        \
  type name() const noexcept { return is_set(bit) ? raw_.name : defaults().name; }
  DYFOS_HPP_FIELD(rover_radius, double, DYFOS_PARAM_ROVER_RADIUS)
  DYFOS_HPP_FIELD(marker_size, double, DYFOS_PARAM_MARKER_SIZE)
  DYFOS_HPP_FIELD(marker_height, double, DYFOS_PARAM_MARKER_HEIGHT)
  DYFOS_HPP_FIELD(viewer_radius, double, DYFOS_PARAM_VIEWER_RADIUS)
  DYFOS_HPP_FIELD(safety_margin, double, DYFOS_PARAM_SAFETY_MARGIN)
  DYFOS_HPP_FIELD(z_min, double, DYFOS_PARAM_Z_MIN)
  DYFOS_HPP_FIELD(z_max, double, DYFOS_PARAM_Z_MAX)
  DYFOS_HPP_FIELD(camera_pitch, double, DYFOS_PARAM_CAMERA_PITCH)
  DYFOS_HPP_FIELD(f_h, double, DYFOS_PARAM_F_H)
  DYFOS_HPP_FIELD(f_v, double, DYFOS_PARAM_F_V)
  DYFOS_HPP_FIELD(rho_min, double, DYFOS_PARAM_RHO_MIN)
  DYFOS_HPP_FIELD(rho_max, double, DYFOS_PARAM_RHO_MAX)
  DYFOS_HPP_FIELD(kappa, double, DYFOS_PARAM_KAPPA)
  DYFOS_HPP_FIELD(lambda, double, DYFOS_PARAM_LAMBDA)
  DYFOS_HPP_FIELD(perimeter_points, std::uint32_t, DYFOS_PARAM_PERIMETER_POINTS)
#undef DYFOS_HPP_FIELD
  Params& t_vs(const std::array<double, 3>& v) noexcept {
    for (std::size_t i = 0; i < 3; ++i) raw_.t_vs[i] = v[i];
    raw_.set |= DYFOS_PARAM_T_VS;
    return *this;
  }
  std::array<double, 3> t_vs() const noexcept {
    const dyfos_params& from = is_set(DYFOS_PARAM_T_VS) ? raw_ : defaults();
    return {from.t_vs[0], from.t_vs[1], from.t_vs[2]};
  }
  Params& model(Model m) noexcept {
    raw_.model = static_cast<std::uint32_t>(m);
    raw_.set |= DYFOS_PARAM_MODEL;
    return *this;
  }
  Model model() const noexcept {
    return static_cast<Model>(is_set(DYFOS_PARAM_MODEL) ? raw_.model : defaults().model);
  }
  /// Whether every field of `bits` (DYFOS_PARAM_* bits) is given.
  bool is_set(std::uint32_t bits) const noexcept { return (raw_.set & bits) == bits; }
  /// Wraps a C struct as it is (its `set` bits included).
  static Params from_raw(const dyfos_params& raw) noexcept {
    Params p;
    p.raw_ = raw;
    return p;
  }
  /// The C struct.
  const dyfos_params& raw() const noexcept { return raw_; }

 private:
  /// The SPEC defaults, with `set` 0 (dyfos_params_init cannot fail on a valid pointer).
  static const dyfos_params& defaults() noexcept {
    static const dyfos_params values = [] {
      dyfos_params p{};
      dyfos_params_init(&p);
      return p;
    }();
    return values;
  }
  dyfos_params raw_;
};

/// A rendezvous query: the map, the rover's belief, and how to search.
struct RendezvousRequest {
  std::uint64_t map = 0;
  std::array<double, 3> mean{};                  ///< (x, y, θ): m, m, rad
  std::array<std::array<double, 3>, 3> cov{};    ///< Σ⁻ rows, symmetric positive definite
  Algorithm algorithm = Algorithm::Dyfos;
  std::uint64_t seed = 0;                        ///< same request + seed = same answer, bit for bit
  Params params;                                 ///< SPEC defaults unless set
  /// Most candidates to evaluate; none = the algorithm's own limits. 0 can find
  /// nothing: InvalidRequestError (DYFOS_STATUS_MALFORMED_REQUEST).
  std::optional<std::uint64_t> budget;
  /// Answer with the best pose so far when it passes (counted from the daemon's
  /// receipt); none = no deadline. Must be positive (else InvalidRequestError,
  /// DYFOS_STATUS_INVALID_DEADLINE) and at most an hour.
  std::optional<std::chrono::microseconds> deadline;
  /// The map must be at this version before `deltas_json`; none = any version. The
  /// version counts deltas, not batches: each delta applied adds 1.
  std::optional<std::uint64_t> expected_version;
  /// Map deltas applied before the search (a JSON array, as `dyfos map apply`
  /// reads; at most DYFOS_MAX_INLINE_RECORDS records); they stay applied whatever
  /// the search finds, each adding 1 to the map's version.
  std::optional<std::string> deltas_json;

  /// The request for a scenario's rover (its belief and parameters) on map `map`.
  static RendezvousRequest from_scenario(const std::string& scenario_json, std::uint64_t map) {
    dyfos_rendezvous_request c{};
    detail::check(dyfos_rendezvous_request_from_scenario(scenario_json.c_str(), map, &c));
    RendezvousRequest r;
    r.map = c.map;
    for (std::size_t i = 0; i < 3; ++i) {
      r.mean[i] = c.mean[i];
      for (std::size_t j = 0; j < 3; ++j) r.cov[i][j] = c.cov[i][j];
    }
    r.params = Params::from_raw(c.params);
    return r;
  }

  /// The C struct; `deltas_json` points into this object, so keep it alive. Throws
  /// InvalidRequestError for a budget of 0 or a deadline that is not positive.
  dyfos_rendezvous_request raw() const {
    if (budget && *budget == 0) {
      throw InvalidRequestError(DYFOS_STATUS_MALFORMED_REQUEST,
                                "budget = 0 evaluations can find nothing; leave it empty for the algorithm's own limits");
    }
    if (deadline && deadline->count() <= 0) {
      throw InvalidRequestError(DYFOS_STATUS_INVALID_DEADLINE,
                                "deadline = " + std::to_string(deadline->count()) +
                                    " us: give a positive duration, or leave it empty for no deadline");
    }
    dyfos_rendezvous_request c{};
    c.map = map;
    for (std::size_t i = 0; i < 3; ++i) {
      c.mean[i] = mean[i];
      for (std::size_t j = 0; j < 3; ++j) c.cov[i][j] = cov[i][j];
    }
    c.algorithm = static_cast<std::uint32_t>(algorithm);
    c.seed = seed;
    c.params = params.raw();
    c.budget = budget.value_or(0);
    c.deadline_micros = deadline ? static_cast<std::uint64_t>(deadline->count()) : 0;
    c.has_expected_version = expected_version ? 1u : 0u;
    c.expected_version = expected_version.value_or(0);
    c.deltas_json = deltas_json ? deltas_json->c_str() : nullptr;
    return c;
  }
};

/// The optimal sensor pose found (SPEC §8).
class Answer {
 public:
  /// An empty answer (every number 0), to be assigned a real one.
  Answer() noexcept : raw_{} {}
  explicit Answer(const dyfos_answer& raw) noexcept : raw_(raw) {}
  Algorithm algorithm() const noexcept { return static_cast<Algorithm>(raw_.algorithm); }
  /// One of DYFOS_STOP_*; DYFOS_STOP_DEADLINE means the best pose found in time.
  std::uint32_t stop() const noexcept { return raw_.stop; }
  /// The map version searched (after the request's deltas, one version each).
  std::uint64_t map_version() const noexcept { return raw_.map_version; }
  /// x = (ρ, ψ, φ, ψ_v).
  std::array<double, 4> x() const noexcept { return to_array<4>(raw_.x); }
  /// E = ln det Σ⁺.
  double cost() const noexcept { return raw_.cost; }
  std::array<double, 3> sensor_position() const noexcept { return to_array<3>(raw_.sensor_position); }
  /// (x, y, z, w), w ≥ 0.
  std::array<double, 4> sensor_quaternion() const noexcept { return to_array<4>(raw_.sensor_quaternion); }
  std::array<double, 3> viewer_position() const noexcept { return to_array<3>(raw_.viewer_position); }
  double viewer_yaw() const noexcept { return raw_.viewer_yaw; }
  /// Predicted measurement noise R, rows.
  std::array<std::array<double, 2>, 2> R() const noexcept {
    return {to_array<2>(raw_.r[0]), to_array<2>(raw_.r[1])};
  }
  /// Predicted posterior Σ⁺, rows.
  std::array<std::array<double, 3>, 3> posterior() const noexcept {
    return {to_array<3>(raw_.posterior[0]), to_array<3>(raw_.posterior[1]), to_array<3>(raw_.posterior[2])};
  }
  const dyfos_evaluations& evaluations() const noexcept { return raw_.evaluations; }
  std::uint64_t micros() const noexcept { return raw_.micros; }
  /// The JSON text `dyfos solve` prints for this answer.
  std::string to_json() const {
    char* json = nullptr;
    detail::check(dyfos_answer_to_json(&raw_, &json));
    return detail::take(json);
  }
  const dyfos_answer& raw() const noexcept { return raw_; }

 private:
  template <std::size_t N>
  static std::array<double, N> to_array(const double (&a)[N]) noexcept {
    std::array<double, N> out{};
    for (std::size_t i = 0; i < N; ++i) out[i] = a[i];
    return out;
  }
  dyfos_answer raw_;
};

/// A map held by the daemon and its version.
struct MapVersion {
  std::uint64_t map;
  std::uint64_t version;
};

/// A map held by the daemon, as Client::list_maps describes it.
struct MapInfo {
  std::uint64_t map = 0;
  std::uint64_t version = 0;
  /// Another one if the map was deleted and made again under its id (back at version 0).
  std::uint32_t generation = 0;
  std::array<double, 4> bounds{};  ///< x_min, y_min, x_max, y_max, m
  double sun_elevation = 0.0;      ///< rad
  double sun_azimuth = 0.0;        ///< rad
};

/// A connection to one dyfosd. Move-only; closed by the destructor (which waits for
/// a call in progress on another thread). Any method may be called from several
/// threads at once: the library serialises the calls of one client (one request at
/// a time); use one Client per thread for parallel queries. The const methods
/// change nothing of this object (rendezvous commits its request's deltas, if any,
/// to the daemon's map). Every call takes an optional timeout, the longest wait for
/// its reply; none = the client's. A moved-from Client throws InvalidRequestError
/// (DYFOS_STATUS_NULL_PARAMETER) from every call.
class Client {
 public:
  /// Connects to the daemon serving `prefix` (its --prefix) in iceoryx2 `domain`
  /// (its --domain; none = the default), waiting up to `timeout` (> 0), which is
  /// also the client's default call timeout. Throws DaemonGoneError if none serves it.
  explicit Client(const std::string& prefix = "dyfos/", const std::optional<std::string>& domain = std::nullopt,
                  std::chrono::milliseconds timeout = std::chrono::milliseconds(1000)) {
    detail::check(dyfos_client_connect(prefix.c_str(), domain ? domain->c_str() : nullptr,
                                       detail::timeout_ms(timeout), &handle_));
  }
  ~Client() { dyfos_client_free(handle_); }
  Client(const Client&) = delete;
  Client& operator=(const Client&) = delete;
  Client(Client&& other) noexcept : handle_(std::exchange(other.handle_, nullptr)) {}
  Client& operator=(Client&& other) noexcept {
    if (this != &other) {
      dyfos_client_free(handle_);
      handle_ = std::exchange(other.handle_, nullptr);
    }
    return *this;
  }

  using Timeout = std::optional<std::chrono::milliseconds>;

  /// The daemon's health and counters, as the JSON `dyfos stats` prints (`maps`:
  /// how many it holds; list_maps lists them).
  std::string stats_json(Timeout timeout = std::nullopt) const {
    char* json = nullptr;
    detail::check(dyfos_client_stats(live("stats_json"), detail::timeout_ms(timeout), &json));
    return detail::take(json);
  }

  /// Makes sure the daemon holds a scenario's map (SPEC §11 JSON text) under its
  /// content id; its id and version. If the id holds other content (e.g. changed by
  /// deltas), `replace` replaces it, else InvalidRequestError (map_exists).
  MapVersion upload_scenario(const std::string& scenario_json, bool replace = false, Timeout timeout = std::nullopt) {
    MapVersion out{};
    detail::check(dyfos_client_upload_scenario(live("upload_scenario"), detail::timeout_ms(timeout),
                                               scenario_json.c_str(), replace ? 1u : 0u, &out.map, &out.version));
    return out;
  }

  /// Creates (or, with `replace`, replaces) map `map` from an OctoMap `.bt` file's bytes;
  /// OctoMap's cell (0, 0, 0) has its minimum corner at `origin`. Returns the version.
  std::uint64_t upload_octomap(std::uint64_t map, const std::vector<std::uint8_t>& bt,
                               const std::array<double, 3>& origin, const std::array<double, 4>& bounds,
                               double sun_elevation, double sun_azimuth, bool replace = false,
                               Timeout timeout = std::nullopt) {
    std::uint64_t version = 0;
    detail::check(dyfos_client_upload_octomap(live("upload_octomap"), detail::timeout_ms(timeout), map, bt.data(),
                                              bt.size(), origin.data(), bounds.data(), sun_elevation, sun_azimuth,
                                              replace ? 1u : 0u, &version));
    return version;
  }

  /// Creates an empty map (version 0) with bounds (x_min, y_min, x_max, y_max) and
  /// the sun (elevation, azimuth).
  std::uint64_t create_map(std::uint64_t map, const std::array<double, 4>& bounds, double sun_elevation,
                           double sun_azimuth, Timeout timeout = std::nullopt) {
    std::uint64_t version = 0;
    detail::check(dyfos_client_create_map(live("create_map"), detail::timeout_ms(timeout), map, bounds.data(),
                                          sun_elevation, sun_azimuth, &version));
    return version;
  }

  /// Applies map deltas (a JSON array, at most DYFOS_MAX_BATCH_RECORDS records)
  /// atomically; the new version: the old one plus the number of deltas (the version
  /// counts deltas, not batches). A larger batch throws OverCapacityError.
  std::uint64_t apply(std::uint64_t map, const std::string& deltas_json,
                      std::optional<std::uint64_t> expected_version = std::nullopt, Timeout timeout = std::nullopt) {
    std::uint64_t version = 0;
    detail::check(dyfos_client_apply(live("apply"), detail::timeout_ms(timeout), map, deltas_json.c_str(),
                                     expected_version.value_or(DYFOS_ANY_VERSION), &version));
    return version;
  }

  /// The map as JSON (version, bounds, sun, obstacles, voxels).
  std::string snapshot(std::uint64_t map, Timeout timeout = std::nullopt) const {
    char* json = nullptr;
    detail::check(dyfos_client_snapshot(live("snapshot"), detail::timeout_ms(timeout), map, &json));
    return detail::take(json);
  }

  /// Deletes map `map`; with `expected_version`, only if it is at that version.
  void delete_map(std::uint64_t map, std::optional<std::uint64_t> expected_version = std::nullopt,
                  Timeout timeout = std::nullopt) {
    detail::check(dyfos_client_delete_map(live("delete_map"), detail::timeout_ms(timeout), map,
                                          expected_version.value_or(DYFOS_ANY_VERSION)));
  }

  /// Every map the daemon holds, in id order (one request per map, all within the
  /// timeout). Maps made or deleted while it lists may or may not be in the list.
  std::vector<MapInfo> list_maps(Timeout timeout = std::nullopt) const {
    std::vector<dyfos_map_info> raw(DYFOS_MAX_MAPS);
    std::size_t count = 0;
    detail::check(
        dyfos_client_list_maps(live("list_maps"), detail::timeout_ms(timeout), raw.data(), raw.size(), &count));
    // At most DYFOS_MAX_MAPS are described; never read past what was written.
    if (count < raw.size()) raw.resize(count);
    std::vector<MapInfo> maps;
    maps.reserve(raw.size());
    for (const dyfos_map_info& m : raw) {
      MapInfo info;
      info.map = m.map;
      info.version = m.version;
      info.generation = m.generation;
      for (std::size_t i = 0; i < 4; ++i) info.bounds[i] = m.bounds[i];
      info.sun_elevation = m.sun_elevation;
      info.sun_azimuth = m.sun_azimuth;
      maps.push_back(info);
    }
    return maps;
  }

  /// The optimal sensor pose for `request`.
  Answer rendezvous(const RendezvousRequest& request, Timeout timeout = std::nullopt) const {
    dyfos_rendezvous_request c = request.raw();
    dyfos_answer answer{};
    detail::check(dyfos_client_rendezvous(live("rendezvous"), detail::timeout_ms(timeout), &c, &answer));
    return Answer(answer);
  }

  /// Check mode: everything validated, nothing searched; the map version it would search.
  std::uint64_t check(const RendezvousRequest& request, Timeout timeout = std::nullopt) const {
    dyfos_rendezvous_request c = request.raw();
    std::uint64_t version = 0;
    detail::check(dyfos_client_check(live("check"), detail::timeout_ms(timeout), &c, &version));
    return version;
  }

  /// The C handle (still owned by this object; NULL once moved from).
  dyfos_client* handle() const noexcept { return handle_; }

 private:
  /// The handle, or the moved-from error naming the method.
  dyfos_client* live(const char* method) const {
    if (handle_ == nullptr) {
      throw InvalidRequestError(DYFOS_STATUS_NULL_PARAMETER,
                                std::string("dyfos::Client::") + method +
                                    ": this Client was moved from and holds no connection; use the Client it was "
                                    "moved to");
    }
    return handle_;
  }

  dyfos_client* handle_ = nullptr;
};

}  // namespace dyfos

#endif  // DYFOS_HPP
