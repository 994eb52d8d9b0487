// cpp_check: exercises the C++ wrapper (dyfos.hpp) against a real dyfosd; driven
// by client/ffi/tests/c_and_cpp.rs like ffi_check.c (same "--- SECTION" output).
//
// Usage: cpp_check SCENARIO.json PREFIX DOMAIN
#include "dyfos.hpp"

#include <cstring>
#include <fstream>
#include <iostream>
#include <sstream>
#include <thread>
#include <type_traits>

static int failures = 0;

#define EXPECT_TRUE(cond)                                                      \
  do {                                                                         \
    if (!(cond)) {                                                             \
      std::cerr << "cpp_check.cpp:" << __LINE__ << ": expected " #cond "\n"; \
      failures++;                                                              \
    }                                                                          \
  } while (0)

// Expects `body` to throw exactly `Exception` with status `code`.
#define EXPECT_THROW(body, Exception, code)                                                          \
  do {                                                                                               \
    try {                                                                                            \
      body;                                                                                          \
      std::cerr << "cpp_check.cpp:" << __LINE__ << ": " #body " did not throw\n";                    \
      failures++;                                                                                    \
    } catch (const Exception& e) {                                                                   \
      if (e.status() != (code)) {                                                                    \
        std::cerr << "cpp_check.cpp:" << __LINE__ << ": status " << e.name() << ": " << e.what() << "\n"; \
        failures++;                                                                                  \
      }                                                                                              \
    } catch (const std::exception& e) {                                                              \
      std::cerr << "cpp_check.cpp:" << __LINE__ << ": wrong exception: " << e.what() << "\n";        \
      failures++;                                                                                    \
    }                                                                                                \
  } while (0)

static bool same(const dyfos::Answer& a, const dyfos::Answer& b) {
  dyfos_answer x = a.raw(), y = b.raw();
  x.micros = y.micros = 0;
  return std::memcmp(&x, &y, sizeof x) == 0;
}

int main(int argc, char** argv) {
  if (argc != 4) {
    std::cerr << "usage: cpp_check SCENARIO.json PREFIX DOMAIN\n";
    return 2;
  }
  std::ifstream file(argv[1]);
  std::stringstream buffer;
  buffer << file.rdbuf();
  const std::string scenario = buffer.str();
  const std::string prefix = argv[2], domain = argv[3];
  static_assert(!std::is_copy_constructible_v<dyfos::Client>, "a Client is move-only");
  static_assert(std::is_nothrow_move_constructible_v<dyfos::Client>, "a Client moves");
  static_assert(std::is_default_constructible_v<dyfos::Answer>, "an Answer can be declared before it is assigned");
  static_assert(std::is_unsigned_v<decltype(DYFOS_PARAM_LAMBDA)> && std::is_unsigned_v<decltype(DYFOS_PARAMS_ALL_SET)>,
                "the parameter bits are unsigned, like dyfos_params.set");
  static_assert(std::is_unsigned_v<decltype(DYFOS_STATUS_NULL_PARAMETER)>, "status codes are dyfos_status values");

  EXPECT_THROW(dyfos::Client("dyfos-ffi-nobody/", domain, std::chrono::milliseconds(50)), dyfos::DaemonGoneError,
               DYFOS_STATUS_NO_DAEMON);
  EXPECT_THROW(dyfos::Client("bad prefix", domain), dyfos::InvalidRequestError, DYFOS_STATUS_INVALID_ARGUMENT);
  EXPECT_THROW(dyfos::Client(prefix, domain, std::chrono::milliseconds(-5)), dyfos::InvalidRequestError,
               DYFOS_STATUS_INVALID_ARGUMENT);

  dyfos::Client first(prefix, domain, std::chrono::seconds(60));
  dyfos::Client client = std::move(first);  // the moved-from object holds nothing
  EXPECT_TRUE(first.handle() == nullptr && client.handle() != nullptr);
  EXPECT_THROW(first.stats_json(), dyfos::InvalidRequestError, DYFOS_STATUS_NULL_PARAMETER);
  try {
    first.snapshot(1);
  } catch (const dyfos::Error& e) {
    // Says what happened in C++ terms, not which C pointer was NULL.
    EXPECT_TRUE(std::string(e.what()).find("moved from") != std::string::npos);
    EXPECT_TRUE(std::string(e.what()).find("snapshot") != std::string::npos);
    EXPECT_TRUE(std::string(e.what()).find("NULL") == std::string::npos);
  }
  EXPECT_TRUE(client.stats_json().find("\"pid\":") != std::string::npos);

  auto [map, version] = client.upload_scenario(scenario);
  EXPECT_TRUE(version == 0);
  auto request = dyfos::RendezvousRequest::from_scenario(scenario, map);
  request.seed = 7;
  request.expected_version = version;
  dyfos::Answer answer = client.rendezvous(request);
  std::cout << "--- answer dyfos 7\n" << answer.to_json() << "\n";
  EXPECT_TRUE(answer.algorithm() == dyfos::Algorithm::Dyfos && answer.map_version() == version);
  EXPECT_TRUE(answer.x()[0] == answer.raw().x[0] && answer.posterior()[2][2] == answer.raw().posterior[2][2]);
  request.algorithm = dyfos::Algorithm::Random;
  request.seed = 2;
  std::cout << "--- answer random 2\n" << client.rendezvous(request).to_json() << "\n";
  EXPECT_TRUE(client.check(request) == version);

  // The queries are const: callable on a const Client (and from several threads).
  const dyfos::Client& view = client;
  EXPECT_TRUE(view.check(request) == version && view.stats_json().find("\"maps\":") != std::string::npos);
  EXPECT_TRUE(same(view.rendezvous(request), client.rendezvous(request)));

  // One client shared by threads: their calls are serialised, each gets its reply.
  {
    int ok[2] = {0, 0};
    auto work = [&](int i) {
      for (int k = 0; k < 50; ++k) ok[i] += client.check(request) == version;
    };
    std::thread other(work, 1);
    work(0);
    other.join();
    EXPECT_TRUE(ok[0] == 50 && ok[1] == 50);
  }

  // Parameters: left out, given as their defaults, or one set by the builder.
  dyfos::RendezvousRequest defaulted;
  defaulted.map = map;
  defaulted.mean = request.mean;
  defaulted.cov = request.cov;
  dyfos::RendezvousRequest explicit_defaults = defaulted;
  explicit_defaults.params = dyfos::Params::from_json("{}");
  EXPECT_TRUE(defaulted.params.raw().set == 0 && explicit_defaults.params.raw().set == DYFOS_PARAMS_ALL_SET);
  EXPECT_TRUE(same(client.rendezvous(defaulted), client.rendezvous(explicit_defaults)));
  dyfos::RendezvousRequest narrow = defaulted;
  narrow.params = dyfos::Params().rho_max(4.0);
  EXPECT_TRUE(narrow.params.raw().set == DYFOS_PARAM_RHO_MAX);
  dyfos::Answer narrowed = client.rendezvous(narrow);
  EXPECT_TRUE(!same(narrowed, client.rendezvous(defaulted)) && narrowed.x()[0] <= 4.0);
  EXPECT_THROW(dyfos::Params::from_json("{\"rho_mim\": 1}"), dyfos::InvalidRequestError,
               DYFOS_STATUS_INVALID_ARGUMENT);
  EXPECT_THROW(dyfos::Params::from_json("{\"rho_min\": 9}"), dyfos::InvalidRequestError, DYFOS_STATUS_INVALID_PARAMS);

  // Params getters: the value a request uses, the field if given, else the default.
  {
    dyfos::Params p;
    EXPECT_TRUE(p.lambda() == 3.0 && p.rho_max() == 6.0 && p.model() == dyfos::Model::Paper && !p.is_set(DYFOS_PARAM_LAMBDA));
    p.lambda(2.0).t_vs({0.5, 0.0, 0.0});
    EXPECT_TRUE(p.lambda() == 2.0 && p.is_set(DYFOS_PARAM_LAMBDA | DYFOS_PARAM_T_VS) && p.t_vs()[0] == 0.5);
    dyfos_params garbage{};
    garbage.lambda = -1.0;  // ignored: its bit is clear
    EXPECT_TRUE(dyfos::Params::from_raw(garbage).lambda() == 3.0);
    EXPECT_TRUE(dyfos::Params::from_json("{\"kappa\": 2.5}").kappa() == 2.5);
  }
  dyfos::Answer empty;
  EXPECT_TRUE(empty.cost() == 0.0 && empty.map_version() == 0);
  empty = narrowed;
  EXPECT_TRUE(same(empty, narrowed));

  // Each family as its exception.
  dyfos::RendezvousRequest bad = request;
  bad.map = 424242;
  EXPECT_THROW(client.rendezvous(bad), dyfos::UnknownMapError, DYFOS_STATUS_UNKNOWN_MAP);
  bad = request;
  bad.expected_version = version + 3;
  EXPECT_THROW(client.rendezvous(bad), dyfos::VersionMismatchError, DYFOS_STATUS_MAP_VERSION_MISMATCH);
  bad = request;
  bad.cov[2][2] = -1.0;
  EXPECT_THROW(client.rendezvous(bad), dyfos::InvalidRequestError, DYFOS_STATUS_INVALID_BELIEF);
  bad = request;
  bad.params = dyfos::Params().rho_min(9.0);
  EXPECT_THROW(client.rendezvous(bad), dyfos::InvalidRequestError, DYFOS_STATUS_INVALID_PARAMS);
  bad = request;
  bad.algorithm = dyfos::Algorithm::Brute;
  bad.deadline = std::chrono::microseconds(1);
  EXPECT_THROW(client.rendezvous(bad), dyfos::DeadlineExceededError, DYFOS_STATUS_DEADLINE_EXCEEDED);
  bad = request;
  std::string many = "[";
  for (int i = 0; i < 1100; ++i) many += i ? ",{\"clear\": {}}" : "{\"clear\": {}}";
  bad.deltas_json = many + "]";
  // Too many records: its own error, not "busy" (a retry cannot help).
  EXPECT_THROW(client.rendezvous(bad), dyfos::OverCapacityError, DYFOS_STATUS_OVER_CAPACITY);
  bad = request;
  bad.deadline = std::chrono::microseconds(-5);  // not wrapped to 2^64 - 5 us
  EXPECT_THROW(client.rendezvous(bad), dyfos::InvalidRequestError, DYFOS_STATUS_INVALID_DEADLINE);
  bad.deadline = std::chrono::microseconds(0);
  EXPECT_THROW(client.check(bad), dyfos::InvalidRequestError, DYFOS_STATUS_INVALID_DEADLINE);
  bad = request;
  bad.budget = 0;
  EXPECT_THROW(client.rendezvous(bad), dyfos::InvalidRequestError, DYFOS_STATUS_MALFORMED_REQUEST);
  const std::uint64_t tiny = 888000 + map % 1000;
  EXPECT_TRUE(client.create_map(tiny, {-0.2, -0.2, 0.2, 0.2}, 0.7, 2.1) == 0);
  EXPECT_THROW(client.create_map(tiny, {-0.2, -0.2, 0.2, 0.2}, 0.7, 2.1), dyfos::InvalidRequestError,
               DYFOS_STATUS_MAP_EXISTS);
  bad = request;
  bad.map = tiny;
  bad.expected_version.reset();
  EXPECT_THROW(client.rendezvous(bad), dyfos::NoFeasiblePoseError, DYFOS_STATUS_NO_FEASIBLE_POSE);
  EXPECT_THROW(client.apply(tiny, "[{\"clear\": {}}]", 5), dyfos::VersionMismatchError,
               DYFOS_STATUS_MAP_VERSION_MISMATCH);
  EXPECT_TRUE(client.apply(tiny, "[{\"clear\": {}}]", 0) == 1);
  EXPECT_TRUE(client.snapshot(tiny).find("\"version\": 1") != std::string::npos);
  EXPECT_TRUE(client.apply(tiny, "[{\"clear\": {}}, {\"clear\": {}}]", 1) == 3);  // the version counts deltas
  {
    std::string batch = "[";
    for (std::uint32_t i = 0; i <= DYFOS_MAX_BATCH_RECORDS; ++i) batch += i ? ",{\"clear\": {}}" : "{\"clear\": {}}";
    EXPECT_THROW(client.apply(tiny, batch + "]"), dyfos::OverCapacityError, DYFOS_STATUS_OVER_CAPACITY);
  }
  EXPECT_THROW(client.apply(tiny, "[not json"), dyfos::InvalidRequestError, DYFOS_STATUS_MALFORMED_DELTA);
  EXPECT_THROW(client.create_map(tiny + 1, {1.0, 1.0, -1.0, -1.0}, 0.7, 2.1), dyfos::InvalidRequestError,
               DYFOS_STATUS_INVALID_DELTA);
  EXPECT_THROW(client.delete_map(tiny, 2), dyfos::VersionMismatchError, DYFOS_STATUS_MAP_VERSION_MISMATCH);
  {
    // Both maps, in id order, the small one as made and changed; then it is deleted.
    std::vector<dyfos::MapInfo> maps = view.list_maps();
    EXPECT_TRUE(maps.size() == 2);
    if (maps.size() == 2) {
      const dyfos::MapInfo& small = maps[0].map == tiny ? maps[0] : maps[1];
      const dyfos::MapInfo& scenario_map = maps[0].map == tiny ? maps[1] : maps[0];
      EXPECT_TRUE(maps[0].map < maps[1].map && small.map == tiny && scenario_map.map == map);
      EXPECT_TRUE(small.version == 3 && scenario_map.version == version);
      EXPECT_TRUE((small.bounds == std::array<double, 4>{-0.2, -0.2, 0.2, 0.2}));
      EXPECT_TRUE(small.sun_elevation == 0.7 && small.sun_azimuth == 2.1);
      EXPECT_TRUE(small.generation != 0 && scenario_map.generation != 0);
    }
  }
  client.delete_map(tiny, 3);
  EXPECT_THROW(client.snapshot(tiny), dyfos::UnknownMapError, DYFOS_STATUS_UNKNOWN_MAP);
  {
    std::vector<dyfos::MapInfo> maps = client.list_maps(std::chrono::seconds(30));
    EXPECT_TRUE(maps.size() == 1 && maps[0].map == map);
  }
  EXPECT_THROW(first.list_maps(), dyfos::InvalidRequestError, DYFOS_STATUS_NULL_PARAMETER);
  // A timeout for one call; not positive is refused before anything is sent.
  bad = request;
  bad.algorithm = dyfos::Algorithm::Brute;
  bad.deadline = std::chrono::seconds(2);
  EXPECT_THROW(client.rendezvous(bad, std::chrono::milliseconds(1)), dyfos::TimeoutError, DYFOS_STATUS_TIMEOUT);
  EXPECT_THROW(client.check(request, std::chrono::milliseconds(-1)), dyfos::InvalidRequestError,
               DYFOS_STATUS_INVALID_ARGUMENT);
  EXPECT_TRUE(client.check(request, std::chrono::seconds(30)) == version);
  {
    dyfos::Client hasty(prefix, domain, std::chrono::milliseconds(1));
    bad = request;
    bad.algorithm = dyfos::Algorithm::Brute;
    bad.deadline = std::chrono::seconds(2);
    EXPECT_THROW(hasty.rendezvous(bad), dyfos::TimeoutError, DYFOS_STATUS_TIMEOUT);
  }
  // The scenario's map changed by a delta: re-uploaded only with replace.
  EXPECT_TRUE(client.apply(map, "[{\"set_sun\": {\"elevation\": 0.3, \"azimuth\": 1.0}}]", version) == version + 1);
  EXPECT_THROW(client.upload_scenario(scenario), dyfos::InvalidRequestError, DYFOS_STATUS_MAP_EXISTS);
  auto replaced = client.upload_scenario(scenario, true);
  EXPECT_TRUE(replaced.map == map && replaced.version == version + 2);

  std::cout << "--- kill" << std::endl;
  std::string line;
  std::getline(std::cin, line);
  try {
    client.stats_json();
    std::cerr << "cpp_check.cpp: stats after the daemon was killed did not throw\n";
    failures++;
  } catch (const dyfos::DaemonGoneError& e) {
    EXPECT_TRUE(e.kind() == dyfos::ErrorKind::DaemonGone);
  }
  std::cout << "--- done" << std::endl;
  if (failures) std::cerr << failures << " expectation(s) failed\n";
  return failures ? 1 : 0;
}
