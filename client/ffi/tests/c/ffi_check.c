/*
 * ffi_check: exercises the whole C API against a real dyfosd; driven by
 * client/ffi/tests/c_and_cpp.rs, which compares what it prints with `dyfos`.
 *
 * Usage: ffi_check SCENARIO.json PREFIX DOMAIN
 *
 * Every expectation that fails is printed to stderr and makes the exit code 1.
 * stdout carries sections the driver reads, each starting with a line "--- NAME":
 *   --- answer ALGORITHM SEED   the answer's JSON (dyfos_answer_to_json)
 *   --- snapshot MAP            the snapshot JSON of the small map, after the deltas of
 *                               $DYFOS_TEST_DELTAS (a file of every kind, docs/deltas.md)
 *   --- octomap                 the version of the OctoMap map (with $DYFOS_TEST_OCTOMAP set)
 *   --- maps                    dyfos_client_list_maps' maps just before --- kill, one a line:
 *                               map version generation x_min y_min x_max y_max elevation azimuth
 *   --- kill                    the driver kills the daemon, then writes a line to stdin
 *   --- done
 */
#include "dyfos.h"

#include <stddef.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

static int failures = 0;

static void expect_status(const char *what, int line, dyfos_status got, dyfos_status want) {
  if (got != want) {
    char message[1024];
    dyfos_last_error(message, sizeof message);
    fprintf(stderr, "ffi_check.c:%d: %s returned %u (%s), expected %u (%s): %s\n", line, what, got,
            dyfos_status_name(got), want, dyfos_status_name(want), message);
    failures++;
  }
}

#define EXPECT(call, code) expect_status(#call, __LINE__, (call), (code))
#define EXPECT_TRUE(cond)                                                 \
  do {                                                                    \
    if (!(cond)) {                                                        \
      fprintf(stderr, "ffi_check.c:%d: expected %s\n", __LINE__, #cond); \
      failures++;                                                         \
    }                                                                     \
  } while (0)

/* A whole file's bytes and length (NULL if unreadable), followed by a NUL that
 * `len` does not count, so that a text file's bytes are a C string. */
static unsigned char *read_bytes(const char *path, size_t *len) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  fseek(f, 0, SEEK_END);
  long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  unsigned char *bytes = n < 0 ? NULL : malloc((size_t)n + 1);
  if (bytes && fread(bytes, 1, (size_t)n, f) != (size_t)n) {
    free(bytes);
    bytes = NULL;
  }
  if (bytes) bytes[n] = '\0';
  fclose(f);
  *len = (size_t)n;
  return bytes;
}

/* A whole text file as a C string (NULL if unreadable). */
static char *read_file(const char *path) {
  size_t len;
  return (char *)read_bytes(path, &len);
}

/* Two answers equal in every field but the compute time. */
static int same_answer(dyfos_answer a, dyfos_answer b) {
  a.micros = 0;
  b.micros = 0;
  return memcmp(&a, &b, sizeof a) == 0;
}

static void print_answer(dyfos_client *client, const dyfos_rendezvous_request *request, const char *algorithm) {
  dyfos_answer answer;
  dyfos_status s = dyfos_client_rendezvous(client, 0, request, &answer);
  EXPECT(s, DYFOS_STATUS_OK);
  if (s != DYFOS_STATUS_OK) return;
  char *json = NULL;
  EXPECT(dyfos_answer_to_json(&answer, &json), DYFOS_STATUS_OK);
  printf("--- answer %s %llu\n%s\n", algorithm, (unsigned long long)request->seed, json);
  dyfos_string_free(json);
}

int main(int argc, char **argv) {
  if (argc != 4) {
    fprintf(stderr, "usage: ffi_check SCENARIO.json PREFIX DOMAIN\n");
    return 2;
  }
  char *scenario = read_file(argv[1]);
  if (!scenario) {
    fprintf(stderr, "cannot read %s\n", argv[1]);
    return 2;
  }
  const char *prefix = argv[2], *domain = argv[3];

  /* Connecting: bad arguments, no daemon, then the real one. */
  dyfos_client *client = (dyfos_client *)1;
  EXPECT(dyfos_client_connect(prefix, domain, 1000, NULL), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_connect("bad prefix", domain, 1000, &client), DYFOS_STATUS_INVALID_ARGUMENT);
  EXPECT_TRUE(client == NULL);
  EXPECT(dyfos_client_connect(prefix, domain, 0, &client), DYFOS_STATUS_INVALID_ARGUMENT);
  EXPECT(dyfos_client_connect("dyfos-ffi-nobody/", domain, 50, &client), DYFOS_STATUS_NO_DAEMON);
  EXPECT_TRUE(client == NULL);
  EXPECT(dyfos_client_connect(prefix, domain, 60000, &client), DYFOS_STATUS_OK);
  if (client == NULL) return 1;

  /* Stats. */
  char *stats = NULL;
  EXPECT(dyfos_client_stats(client, 0, &stats), DYFOS_STATUS_OK);
  EXPECT_TRUE(stats != NULL && strstr(stats, "\"pid\":") != NULL && strstr(stats, "\"maps\":") != NULL);
  dyfos_string_free(stats);

  /* The scenario's map: uploaded once, then reused. */
  uint64_t map = 0, version = 99, again = 0, version_again = 99;
  EXPECT(dyfos_client_upload_scenario(client, 0, scenario, 0, &map, &version), DYFOS_STATUS_OK);
  EXPECT(dyfos_client_upload_scenario(client, 0, scenario, 0, &again, &version_again), DYFOS_STATUS_OK);
  EXPECT_TRUE(map == again && version == 0 && version_again == 0);
  EXPECT(dyfos_client_upload_scenario(client, 0, "{\"bounds\": [", 0, &again, NULL), DYFOS_STATUS_INVALID_ARGUMENT);

  /* An OctoMap .bt: uploaded, a truncated copy refused before sending, replaced. */
  const char *bt_path = getenv("DYFOS_TEST_OCTOMAP");
  if (bt_path) {
    size_t bt_len = 0;
    unsigned char *bt = read_bytes(bt_path, &bt_len);
    EXPECT_TRUE(bt != NULL && bt_len > 100);
    double origin[3] = {0.0, 0.0, 0.32}, area[4] = {-12.0, -8.0, 31.0, 10.0};
    uint64_t at = 99;
    EXPECT(dyfos_client_upload_octomap(client, 0, 0xB7, bt, bt_len, origin, area, 0.6, 2.4, 0, &at), DYFOS_STATUS_OK);
    EXPECT_TRUE(at == 0);
    EXPECT(dyfos_client_upload_octomap(client, 0, 0xB8, bt, bt_len - 1, origin, area, 0.6, 2.4, 0, NULL),
           DYFOS_STATUS_INVALID_DELTA);
    EXPECT(dyfos_client_upload_octomap(client, 0, 0xB8, NULL, 0, origin, area, 0.6, 2.4, 0, NULL),
           DYFOS_STATUS_NULL_PARAMETER);
    EXPECT(dyfos_client_upload_octomap(client, 0, 0xB7, bt, bt_len, origin, area, 0.6, 2.4, 0, NULL),
           DYFOS_STATUS_MAP_EXISTS);
    EXPECT(dyfos_client_upload_octomap(client, 0, 0xB8, bt, bt_len, origin, area, 0.6, 2.4, 2, NULL),
           DYFOS_STATUS_INVALID_ARGUMENT);
    EXPECT(dyfos_client_upload_octomap(client, 0, 0xB7, bt, bt_len, NULL, area, 0.6, 2.4, 1, &at), DYFOS_STATUS_OK);
    printf("--- octomap\nversion=%llu\n", (unsigned long long)at);
    free(bt);
  }
  EXPECT(dyfos_client_upload_scenario(client, 0, NULL, 0, &again, NULL), DYFOS_STATUS_NULL_PARAMETER);

  /* Answers, compared with `dyfos solve` by the driver. */
  dyfos_rendezvous_request request;
  EXPECT(dyfos_rendezvous_request_from_scenario(scenario, map, &request), DYFOS_STATUS_OK);
  EXPECT_TRUE(request.params.set == DYFOS_PARAMS_ALL_SET && request.map == map);
  request.seed = 7;
  request.has_expected_version = 1;
  request.expected_version = version;
  print_answer(client, &request, "dyfos");
  request.algorithm = DYFOS_ALGORITHM_CENTER;
  request.seed = 3;
  print_answer(client, &request, "center");
  request.algorithm = DYFOS_ALGORITHM_DYFOS_SCIPY;
  request.seed = 0;
  print_answer(client, &request, "dyfos-scipy");

  /* Parameters left at their default (set = 0) equal the defaults given explicitly:
   * the scenario's params are the defaults ({"model": "paper"}). */
  dyfos_rendezvous_request defaulted;
  EXPECT(dyfos_rendezvous_request_init(&defaulted), DYFOS_STATUS_OK);
  EXPECT_TRUE(defaulted.params.set == 0 && defaulted.algorithm == DYFOS_ALGORITHM_DYFOS && defaulted.seed == 0 &&
              defaulted.has_expected_version == 0 && defaulted.deltas_json == NULL);
  dyfos_params from_json;
  EXPECT(dyfos_params_from_json("{}", &from_json), DYFOS_STATUS_OK);
  EXPECT(dyfos_params_from_json("{\"rho_mim\": 2}", &from_json), DYFOS_STATUS_INVALID_ARGUMENT);
  EXPECT(dyfos_params_from_json("{}", &from_json), DYFOS_STATUS_OK);
  defaulted.map = map;
  memcpy(defaulted.mean, request.mean, sizeof request.mean);
  memcpy(defaulted.cov, request.cov, sizeof request.cov);
  dyfos_rendezvous_request explicit_defaults = defaulted;
  explicit_defaults.params = from_json;
  EXPECT_TRUE(explicit_defaults.params.set == DYFOS_PARAMS_ALL_SET);
  /* Every field up to `set` (the struct's tail padding is not compared). */
  EXPECT_TRUE(memcmp(&request.params, &from_json, offsetof(dyfos_params, set) + sizeof from_json.set) == 0);
  dyfos_answer left_out, given, repeated;
  EXPECT(dyfos_client_rendezvous(client, 0, &defaulted, &left_out), DYFOS_STATUS_OK);
  EXPECT(dyfos_client_rendezvous(client, 0, &explicit_defaults, &given), DYFOS_STATUS_OK);
  EXPECT(dyfos_client_rendezvous(client, 0, &defaulted, &repeated), DYFOS_STATUS_OK);
  EXPECT_TRUE(same_answer(left_out, given));
  EXPECT_TRUE(same_answer(left_out, repeated));
  EXPECT_TRUE(left_out.algorithm == DYFOS_ALGORITHM_DYFOS && left_out.map_version == version);
  /* One parameter given changes the answer; the others stay at their default. */
  dyfos_rendezvous_request one_param = defaulted;
  one_param.params.rho_max = 4.0;
  one_param.params.set = DYFOS_PARAM_RHO_MAX;
  dyfos_answer changed;
  EXPECT(dyfos_client_rendezvous(client, 0, &one_param, &changed), DYFOS_STATUS_OK);
  EXPECT_TRUE(!same_answer(left_out, changed) && changed.x[0] <= 4.0);

  /* Check mode. */
  uint64_t checked = 99;
  EXPECT(dyfos_client_check(client, 0, &request, &checked), DYFOS_STATUS_OK);
  EXPECT_TRUE(checked == version);

  /* Every error family. */
  dyfos_answer answer;
  dyfos_rendezvous_request bad = request;
  bad.map = 424242;
  EXPECT(dyfos_client_rendezvous(client, 0, &bad, &answer), DYFOS_STATUS_UNKNOWN_MAP);
  char message[512];
  EXPECT_TRUE(dyfos_last_error(message, sizeof message) > 0 && strstr(message, "424242") != NULL);
  bad = request;
  bad.expected_version = version + 5;
  EXPECT(dyfos_client_rendezvous(client, 0, &bad, &answer), DYFOS_STATUS_MAP_VERSION_MISMATCH);
  EXPECT(dyfos_client_check(client, 0, &bad, &checked), DYFOS_STATUS_MAP_VERSION_MISMATCH);
  bad = request;
  bad.cov[0][1] = 0.3; /* not symmetric */
  EXPECT(dyfos_client_rendezvous(client, 0, &bad, &answer), DYFOS_STATUS_INVALID_BELIEF);
  bad = request;
  bad.algorithm = 9;
  EXPECT(dyfos_client_rendezvous(client, 0, &bad, &answer), DYFOS_STATUS_INVALID_ALGORITHM);
  bad = request;
  bad.params.rho_min = 9.0; /* > rho_max */
  EXPECT(dyfos_client_rendezvous(client, 0, &bad, &answer), DYFOS_STATUS_INVALID_PARAMS);
  EXPECT_TRUE(dyfos_last_error(message, sizeof message) > 0 && strstr(message, "rho_min") != NULL);
  bad = request;
  bad.params.set = 1u << 20;
  EXPECT(dyfos_client_rendezvous(client, 0, &bad, &answer), DYFOS_STATUS_INVALID_PARAMS);
  bad = request;
  bad.deadline_micros = 3600000001ull;
  EXPECT(dyfos_client_rendezvous(client, 0, &bad, &answer), DYFOS_STATUS_INVALID_DEADLINE);
  bad = request;
  bad.algorithm = DYFOS_ALGORITHM_BRUTE;
  bad.deadline_micros = 1; /* passes before a worker takes it */
  EXPECT(dyfos_client_rendezvous(client, 0, &bad, &answer), DYFOS_STATUS_DEADLINE_EXCEEDED);
  bad = request;
  bad.deltas_json = "[{\"remove_obstacle\": {\"id\": 404}}]";
  EXPECT(dyfos_client_check(client, 0, &bad, &checked), DYFOS_STATUS_INVALID_DELTA);
  bad.deltas_json = "[not json";
  EXPECT(dyfos_client_rendezvous(client, 0, &bad, &answer), DYFOS_STATUS_MALFORMED_DELTA);
  {
    /* More inline deltas than a request may carry: over capacity, refused before sending. */
    size_t n = 1100;
    char *many = malloc(n * 16 + 3);
    strcpy(many, "[");
    for (size_t i = 0; i < n; i++) strcat(many, i ? ",{\"clear\": {}}" : "{\"clear\": {}}");
    strcat(many, "]");
    bad.deltas_json = many;
    EXPECT(dyfos_client_rendezvous(client, 0, &bad, &answer), DYFOS_STATUS_OVER_CAPACITY);
    free(many);
  }

  /* A small map of our own: no pose is feasible in it. */
  const double tiny[4] = {-0.2, -0.2, 0.2, 0.2};
  uint64_t tiny_map = 777000 + (uint64_t)(map % 1000), tiny_version = 99;
  EXPECT(dyfos_client_create_map(client, 0, tiny_map, tiny, 0.7, 2.1, &tiny_version), DYFOS_STATUS_OK);
  EXPECT_TRUE(tiny_version == 0);
  EXPECT(dyfos_client_create_map(client, 0, tiny_map, tiny, 0.7, 2.1, NULL), DYFOS_STATUS_MAP_EXISTS);
  const double inverted[4] = {1.0, 1.0, -1.0, -1.0};
  EXPECT(dyfos_client_create_map(client, 0, tiny_map + 1, inverted, 0.7, 2.1, NULL), DYFOS_STATUS_INVALID_DELTA);
  /* The same check gives the same code whichever call makes it: a sun below the
   * horizon's limit, as an argument here and as a delta the daemon checks. */
  EXPECT(dyfos_client_create_map(client, 0, tiny_map + 1, tiny, 5.0, 2.1, NULL), DYFOS_STATUS_INVALID_DELTA);
  EXPECT(dyfos_client_apply(client, 0, tiny_map, "[{\"set_sun\": {\"elevation\": 5.0, \"azimuth\": 2.1}}]",
                            DYFOS_ANY_VERSION, NULL),
         DYFOS_STATUS_INVALID_DELTA);
  bad = request;
  bad.map = tiny_map;
  bad.has_expected_version = 0;
  EXPECT(dyfos_client_rendezvous(client, 0, &bad, &answer), DYFOS_STATUS_NO_FEASIBLE_POSE);
  uint64_t applied = 99;
  EXPECT(dyfos_client_apply(client, 0, tiny_map, "[{\"remove_obstacle\": {\"id\": 5}}]", DYFOS_ANY_VERSION, &applied),
         DYFOS_STATUS_INVALID_DELTA);
  const char *clear = "[{\"clear\": {}}]";
  EXPECT(dyfos_client_apply(client, 0, tiny_map, clear, 3, &applied), DYFOS_STATUS_MAP_VERSION_MISMATCH);
  EXPECT(dyfos_client_apply(client, 0, tiny_map, "{}", 0, &applied), DYFOS_STATUS_MALFORMED_DELTA);
  EXPECT(dyfos_client_apply(client, 0, tiny_map, "[{\"teleport\": 1}]", 0, &applied), DYFOS_STATUS_MALFORMED_DELTA);
  EXPECT(dyfos_client_apply(client, 0, 424242, clear, DYFOS_ANY_VERSION, &applied), DYFOS_STATUS_UNKNOWN_MAP);
  EXPECT(dyfos_client_apply(client, 0, tiny_map, clear, 0, &applied), DYFOS_STATUS_OK);
  EXPECT_TRUE(applied == 1);
  /* The old spelling is refused with the kind's new name and an example of it. */
  EXPECT(dyfos_client_apply(client, 0, tiny_map, "[\"Clear\"]", DYFOS_ANY_VERSION, &applied),
         DYFOS_STATUS_MALFORMED_DELTA);
  EXPECT_TRUE(dyfos_last_error(message, sizeof message) > 0 && strstr(message, "deltas[0]") != NULL &&
              strstr(message, "a valid clear: {\"clear\": {}}") != NULL);
  /* A request zeroed with {0} asks for any version (the map is at 1 now). */
  {
    dyfos_rendezvous_request zeroed = {0};
    zeroed.map = tiny_map;
    memcpy(zeroed.mean, request.mean, sizeof request.mean);
    memcpy(zeroed.cov, request.cov, sizeof request.cov);
    checked = 99;
    EXPECT(dyfos_client_check(client, 0, &zeroed, &checked), DYFOS_STATUS_OK);
    EXPECT_TRUE(checked == 1);
    zeroed.has_expected_version = 1; /* and expected_version 0: a real version, not "any" */
    EXPECT(dyfos_client_check(client, 0, &zeroed, &checked), DYFOS_STATUS_MAP_VERSION_MISMATCH);
    zeroed.expected_version = 1;
    EXPECT(dyfos_client_check(client, 0, &zeroed, NULL), DYFOS_STATUS_OK); /* the version is optional */
    zeroed.has_expected_version = 2;
    EXPECT(dyfos_client_check(client, 0, &zeroed, NULL), DYFOS_STATUS_INVALID_ARGUMENT);
  }
  const char *deltas_path = getenv("DYFOS_TEST_DELTAS");
  if (deltas_path) {
    char *deltas = read_file(deltas_path);
    EXPECT_TRUE(deltas != NULL);
    if (deltas) EXPECT(dyfos_client_apply(client, 0, tiny_map, deltas, 1, &applied), DYFOS_STATUS_OK);
    free(deltas);
  }
  char *snapshot = NULL;
  EXPECT(dyfos_client_snapshot(client, 0, tiny_map, &snapshot), DYFOS_STATUS_OK);
  if (snapshot) printf("--- snapshot %llu\n%s\n", (unsigned long long)tiny_map, snapshot);
  dyfos_string_free(snapshot);
  snapshot = NULL;
  EXPECT(dyfos_client_snapshot(client, 0, 424242, &snapshot), DYFOS_STATUS_UNKNOWN_MAP);
  EXPECT_TRUE(snapshot == NULL);

  /* The version counts deltas, not batches; deleting frees the id. */
  {
    uint64_t counted = tiny_map + 2, at = 99;
    EXPECT(dyfos_client_create_map(client, 0, counted, tiny, 0.7, 2.1, NULL), DYFOS_STATUS_OK);
    EXPECT(dyfos_client_apply(client, 0, counted, "[{\"clear\": {}}, {\"clear\": {}}, {\"clear\": {}}]", 0, &at), DYFOS_STATUS_OK);
    EXPECT_TRUE(at == 3);
    EXPECT(dyfos_client_apply(client, 0, counted, "[]", 3, &at), DYFOS_STATUS_OK);
    EXPECT_TRUE(at == 3); /* an empty batch changes nothing */
    EXPECT(dyfos_client_apply(client, 0, counted,
                              "[{\"set_sun\": {\"elevation\": 0.5, \"azimuth\": 1.0}}, {\"clear\": {}}]", 3, &at),
           DYFOS_STATUS_OK);
    EXPECT_TRUE(at == 5);
    EXPECT(dyfos_client_delete_map(client, 0, counted, 4), DYFOS_STATUS_MAP_VERSION_MISMATCH);
    EXPECT(dyfos_client_delete_map(client, 0, counted, 5), DYFOS_STATUS_OK);
    EXPECT(dyfos_client_delete_map(client, 0, counted, DYFOS_ANY_VERSION), DYFOS_STATUS_UNKNOWN_MAP);
    EXPECT(dyfos_client_snapshot(client, 0, counted, &snapshot), DYFOS_STATUS_UNKNOWN_MAP);
    EXPECT(dyfos_client_create_map(client, 0, counted, tiny, 0.7, 2.1, &at), DYFOS_STATUS_OK);
    EXPECT_TRUE(at == 0);
    EXPECT(dyfos_client_delete_map(client, 0, counted, DYFOS_ANY_VERSION), DYFOS_STATUS_OK);
  }

  /* Listing: every map in id order, whole, cut to the array, or only counted. */
  {
    uint64_t made[3];
    size_t n = 0;
    made[n++] = map;
    made[n++] = tiny_map;
    if (bt_path) made[n++] = 0xB7;
    for (size_t i = 1; i < n; i++) /* in id order */
      for (size_t j = i; j > 0 && made[j - 1] > made[j]; j--) {
        uint64_t t = made[j];
        made[j] = made[j - 1];
        made[j - 1] = t;
      }
    static dyfos_map_info maps[DYFOS_MAX_MAPS];
    size_t count = 99;
    EXPECT(dyfos_client_list_maps(client, 0, maps, DYFOS_MAX_MAPS, &count), DYFOS_STATUS_OK);
    EXPECT_TRUE(count == n);
    for (size_t i = 0; i < n && i < count; i++) EXPECT_TRUE(maps[i].map == made[i] && maps[i].generation != 0);
    /* A map of known content: listed with its version, bounds and sun; gone once deleted. */
    uint64_t listed = 0xFFFFFFFFFFFFFFFEull, at = 99; /* past every other id: listed last */
    EXPECT(dyfos_client_create_map(client, 0, listed, tiny, 0.7, 2.1, NULL), DYFOS_STATUS_OK);
    EXPECT(dyfos_client_apply(client, 0, listed, "[{\"clear\": {}}, {\"set_sun\": {\"elevation\": 0.5, \"azimuth\": 1.0}}]",
                              0, &at),
           DYFOS_STATUS_OK);
    EXPECT(dyfos_client_list_maps(client, 0, maps, DYFOS_MAX_MAPS, &count), DYFOS_STATUS_OK);
    EXPECT_TRUE(count == n + 1);
    if (count == n + 1) {
      dyfos_map_info last = maps[n];
      EXPECT_TRUE(last.map == listed && last.version == 2 && at == 2 && last.generation != 0);
      EXPECT_TRUE(memcmp(last.bounds, tiny, sizeof tiny) == 0 && last.sun_elevation == 0.5 && last.sun_azimuth == 1.0);
    }
    /* A smaller array: the first maps, and the whole count; the rest untouched. */
    dyfos_map_info two[2];
    memset(two, 0x5A, sizeof two);
    dyfos_map_info untouched = two[1];
    EXPECT(dyfos_client_list_maps(client, 0, two, 1, &count), DYFOS_STATUS_OK);
    EXPECT_TRUE(count == n + 1 && two[0].map == made[0] && memcmp(&two[1], &untouched, sizeof untouched) == 0);
    count = 99;
    EXPECT(dyfos_client_list_maps(client, 0, NULL, 0, &count), DYFOS_STATUS_OK); /* the count only */
    EXPECT_TRUE(count == n + 1);
    EXPECT(dyfos_client_list_maps(client, 0, NULL, 2, &count), DYFOS_STATUS_NULL_PARAMETER);
    EXPECT(dyfos_client_list_maps(client, 0, two, 2, NULL), DYFOS_STATUS_NULL_PARAMETER);
    EXPECT(dyfos_client_list_maps(NULL, 0, two, 2, &count), DYFOS_STATUS_NULL_PARAMETER);
    EXPECT_TRUE(count == n + 1); /* untouched on failure */
    EXPECT(dyfos_client_delete_map(client, 0, listed, 2), DYFOS_STATUS_OK);
    EXPECT(dyfos_client_list_maps(client, 0, maps, DYFOS_MAX_MAPS, &count), DYFOS_STATUS_OK);
    EXPECT_TRUE(count == n && maps[n - 1].map == made[n - 1]);
  }

  /* A timeout for one call, shorter than the handle's (60 s). */
  bad = request;
  bad.algorithm = DYFOS_ALGORITHM_BRUTE;
  bad.deadline_micros = 2000000;
  EXPECT(dyfos_client_rendezvous(client, 1, &bad, &answer), DYFOS_STATUS_TIMEOUT);
  EXPECT(dyfos_client_check(client, 0, &request, &checked), DYFOS_STATUS_OK); /* the handle goes on */

  /* A reply later than the handle's timeout. */
  dyfos_client *hasty = NULL;
  EXPECT(dyfos_client_connect(prefix, domain, 1, &hasty), DYFOS_STATUS_OK);
  bad = request;
  bad.algorithm = DYFOS_ALGORITHM_BRUTE;
  bad.deadline_micros = 2000000;
  EXPECT(dyfos_client_rendezvous(hasty, 0, &bad, &answer), DYFOS_STATUS_TIMEOUT);
  EXPECT(dyfos_client_free(hasty), DYFOS_STATUS_OK);

  /* NULL and freed handles, NULL inputs and outputs: the null-parameter code. */
  char *out = NULL;
  EXPECT(dyfos_client_stats(NULL, 0, &out), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_stats(hasty, 0, &out), DYFOS_STATUS_NULL_PARAMETER); /* freed above */
  /* The handle is checked first: a NULL or freed handle with bad inputs is the handle's error. */
  EXPECT(dyfos_client_upload_scenario(NULL, 0, "{}", 0, &again, NULL), DYFOS_STATUS_NULL_PARAMETER);
  bad = request;
  bad.mean[0] = strtod("nan", NULL);
  EXPECT(dyfos_client_check(hasty, 0, &bad, &checked), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_check(client, 0, &bad, &checked), DYFOS_STATUS_INVALID_BELIEF);
  EXPECT(dyfos_client_create_map(hasty, 0, 5, inverted, 9.0, 2.1, NULL), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_apply(hasty, 0, tiny_map, "[not json", DYFOS_ANY_VERSION, NULL), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_free(hasty), DYFOS_STATUS_NULL_PARAMETER);        /* double free, detected */
  EXPECT(dyfos_client_free(NULL), DYFOS_STATUS_OK);
  EXPECT(dyfos_client_stats(client, 0, NULL), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_rendezvous(NULL, 0, &request, &answer), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_rendezvous(client, 0, NULL, &answer), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_rendezvous(client, 0, &request, NULL), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_check(client, 0, &request, NULL), DYFOS_STATUS_OK); /* map_version_out may be NULL */
  EXPECT(dyfos_client_check(NULL, 0, &request, &checked), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_upload_scenario(client, 0, scenario, 0, NULL, NULL), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_upload_scenario(NULL, 0, scenario, 0, &again, NULL), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_create_map(NULL, 0, 5, tiny, 0.7, 2.1, NULL), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_create_map(client, 0, 5, NULL, 0.7, 2.1, NULL), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_apply(NULL, 0, tiny_map, "[]", DYFOS_ANY_VERSION, NULL), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_apply(client, 0, tiny_map, NULL, DYFOS_ANY_VERSION, NULL), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_snapshot(NULL, 0, tiny_map, &out), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_client_snapshot(client, 0, tiny_map, NULL), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_answer_to_json(NULL, &out), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_answer_to_json(&left_out, NULL), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_rendezvous_request_init(NULL), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_rendezvous_request_from_scenario(scenario, map, NULL), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_params_init(NULL), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT(dyfos_params_from_json(NULL, &from_json), DYFOS_STATUS_NULL_PARAMETER);
  EXPECT_TRUE(out == NULL);
  dyfos_string_free(NULL);
  /* Freeing a string is no call that fails or succeeds: the last error stays. */
  EXPECT(dyfos_client_snapshot(client, 0, 424242, &out), DYFOS_STATUS_UNKNOWN_MAP);
  dyfos_string_free(NULL);
  EXPECT_TRUE(dyfos_last_error(message, sizeof message) > 0 && strstr(message, "424242") != NULL);
  /* A made-up handle is refused, not dereferenced. */
  EXPECT(dyfos_client_stats((dyfos_client *)0x1234560, 0, &out), DYFOS_STATUS_NULL_PARAMETER);
  /* An answer with codes the library never writes. */
  dyfos_answer forged = left_out;
  forged.stop = 42;
  EXPECT(dyfos_answer_to_json(&forged, &out), DYFOS_STATUS_INVALID_ARGUMENT);

  /* The last error: its full length, and truncation to the buffer. */
  EXPECT(dyfos_client_rendezvous(client, 0, NULL, &answer), DYFOS_STATUS_NULL_PARAMETER);
  size_t full = dyfos_last_error(NULL, 0);
  char small[8];
  EXPECT_TRUE(full > sizeof small && dyfos_last_error(small, sizeof small) == full && strlen(small) < sizeof small);
  EXPECT_TRUE(strcmp(dyfos_status_name(DYFOS_STATUS_UNKNOWN_MAP), "unknown_map") == 0);
  EXPECT_TRUE(strcmp(dyfos_status_name(DYFOS_STATUS_NULL_PARAMETER), "null_parameter") == 0);
  EXPECT_TRUE(strcmp(dyfos_status_name(12345), "unknown_status") == 0);
  EXPECT(dyfos_client_stats(client, 0, &out), DYFOS_STATUS_OK);
  EXPECT_TRUE(dyfos_last_error(NULL, 0) == 0); /* a success clears it */
  dyfos_string_free(out);

  /* Versions: the ABI this header describes is the loaded library's. */
  {
    char numbers[64];
    snprintf(numbers, sizeof numbers, "%u.%u.%u", DYFOS_VERSION_MAJOR, DYFOS_VERSION_MINOR, DYFOS_VERSION_PATCH);
    EXPECT_TRUE(dyfos_abi_version() == DYFOS_ABI_VERSION);
    EXPECT_TRUE(strcmp(dyfos_version(), numbers) == 0);
  }

  /* The scenario's content-id map changed by a delta: uploading the scenario again
   * is map_exists, unless it replaces the map (one more version); deleted, it
   * uploads anew at version 0. */
  {
    uint64_t at = 99, replaced = 99, id = 0;
    EXPECT(dyfos_client_apply(client, 0, map, "[{\"set_sun\": {\"elevation\": 0.3, \"azimuth\": 1.0}}]", version,
                              &at),
           DYFOS_STATUS_OK);
    EXPECT_TRUE(at == version + 1);
    EXPECT(dyfos_client_upload_scenario(client, 0, scenario, 0, &id, NULL), DYFOS_STATUS_MAP_EXISTS);
    EXPECT(dyfos_client_upload_scenario(client, 0, scenario, 1, &id, &replaced), DYFOS_STATUS_OK);
    EXPECT_TRUE(id == map && replaced == at + 1);
    EXPECT(dyfos_client_upload_scenario(client, 0, scenario, 2, &id, NULL), DYFOS_STATUS_INVALID_ARGUMENT);
    EXPECT(dyfos_client_delete_map(client, 0, map, replaced), DYFOS_STATUS_OK);
    EXPECT(dyfos_client_upload_scenario(client, 0, scenario, 0, &id, &replaced), DYFOS_STATUS_OK);
    EXPECT_TRUE(id == map && replaced == 0);
  }

  /* The maps now, for the driver to compare with `dyfos map list`'s. */
  {
    static dyfos_map_info maps[DYFOS_MAX_MAPS];
    size_t count = 0;
    EXPECT(dyfos_client_list_maps(client, 0, maps, DYFOS_MAX_MAPS, &count), DYFOS_STATUS_OK);
    printf("--- maps\n");
    for (size_t i = 0; i < count && i < DYFOS_MAX_MAPS; i++) {
      const dyfos_map_info *m = &maps[i];
      printf("%llu %llu %u %.17g %.17g %.17g %.17g %.17g %.17g\n", (unsigned long long)m->map,
             (unsigned long long)m->version, m->generation, m->bounds[0], m->bounds[1], m->bounds[2], m->bounds[3],
             m->sun_elevation, m->sun_azimuth);
    }
  }

  /* The daemon goes away: the handle says so, and nothing crashes. */
  printf("--- kill\n");
  fflush(stdout);
  char line[16];
  if (!fgets(line, sizeof line, stdin)) {
    fprintf(stderr, "the driver did not answer --- kill\n");
    failures++;
  }
  out = NULL;
  dyfos_status gone = dyfos_client_stats(client, 0, &out);
  EXPECT_TRUE(gone == DYFOS_STATUS_DAEMON_GONE || gone == DYFOS_STATUS_NO_DAEMON);
  EXPECT_TRUE(out == NULL);
  /* The next call tries to reconnect once: no daemon, in this domain. */
  EXPECT(dyfos_client_stats(client, 0, &out), DYFOS_STATUS_NO_DAEMON);
  EXPECT_TRUE(dyfos_last_error(message, sizeof message) > 0 && strstr(message, domain) != NULL);
  EXPECT(dyfos_client_free(client), DYFOS_STATUS_OK);

  printf("--- done\n");
  free(scenario);
  if (failures) fprintf(stderr, "%d expectation(s) failed\n", failures);
  return failures ? 1 : 0;
}
