/*
 * query.c: ask a running dyfosd where the viewer should put its camera, in C.
 *
 *   cc query.c $(pkg-config --cflags --libs dyfos) -o query
 *   ./query SCENARIO.json [PREFIX [DOMAIN [SEED]]]
 *
 * Uploads the scenario's map (SPEC §11), queries its rover, and prints the answer
 * as `dyfos solve --seed SEED SCENARIO.json` prints it.
 */
#include "dyfos.h"

#include <stdio.h>
#include <stdlib.h>

static char *read_file(const char *path) {
  FILE *f = fopen(path, "rb");
  if (!f) return NULL;
  fseek(f, 0, SEEK_END);
  long n = ftell(f);
  fseek(f, 0, SEEK_SET);
  char *text = malloc((size_t)n + 1);
  if (text && fread(text, 1, (size_t)n, f) == (size_t)n) {
    text[n] = '\0';
  } else {
    free(text);
    text = NULL;
  }
  fclose(f);
  return text;
}

int main(int argc, char **argv) {
  if (argc < 2) {
    fprintf(stderr, "usage: %s SCENARIO.json [PREFIX [DOMAIN [SEED]]]\n", argv[0]);
    return 2;
  }
  char *scenario = read_file(argv[1]);
  if (!scenario) {
    fprintf(stderr, "cannot read %s\n", argv[1]);
    return 2;
  }
  const char *prefix = argc > 2 ? argv[2] : NULL; /* NULL: "dyfos/" */
  const char *domain = argc > 3 ? argv[3] : NULL; /* NULL: iceoryx2's default */

  dyfos_client *client = NULL;
  dyfos_rendezvous_request request;
  dyfos_answer answer;
  uint64_t map, version;
  char *json = NULL; /* ours: freed with dyfos_string_free */
  /* 5 s for the daemon to answer, and the default timeout of every call below (their 0). */
  dyfos_status status = dyfos_client_connect(prefix, domain, 5000, &client);
  if (status == DYFOS_STATUS_OK) status = dyfos_client_upload_scenario(client, 0, scenario, 0, &map, &version);
  /* The scenario's belief and parameters; every other field at its default (what a
   * request zeroed with {0}, or filled by dyfos_rendezvous_request_init, holds). */
  if (status == DYFOS_STATUS_OK) status = dyfos_rendezvous_request_from_scenario(scenario, map, &request);
  if (status == DYFOS_STATUS_OK) {
    request.seed = argc > 4 ? strtoull(argv[4], NULL, 10) : 0;
    request.has_expected_version = 1; /* the map as uploaded, not changed since */
    request.expected_version = version;
    status = dyfos_client_rendezvous(client, 0, &request, &answer);
  }
  if (status == DYFOS_STATUS_OK) status = dyfos_answer_to_json(&answer, &json);
  if (status == DYFOS_STATUS_OK) {
    printf("%s\n", json);
  } else {
    char message[512];
    dyfos_last_error(message, sizeof message); /* truncated to fit if longer */
    fprintf(stderr, "dyfos: %s: %s\n", dyfos_status_name(status), message);
  }
  dyfos_string_free(json);
  dyfos_client_free(client); /* NULL is fine */
  free(scenario);
  return status == DYFOS_STATUS_OK ? 0 : 1;
}
