/* minimal_client: one imposed-displacement request to palpated, in plain C.
 *
 * Uses only the C types that idlc generates from idl/palpate.idl (palpate.h)
 * and the Cyclone DDS C API; no palpate library. docs/dds.md quotes this file
 * and explains every step.
 *
 *   minimal_client [MODEL_ID]        (default: sample-organ)
 *
 * Run it like palpated itself: inside a private network namespace, or on a
 * machine whose network may carry DDS traffic. It joins with palpate's
 * loopback-only configuration, so it reaches a daemon on the same host only.
 * Exit code 0 when the reply's status is STATUS_OK, 1 otherwise. */

#include <dds/dds.h>
#include <stdbool.h>
#include <stdio.h>
#include <stdlib.h>
#include <string.h>

#include "palpate.h"
/* PALPATE_LOOPBACK_CONFIG: palpate's own configuration (config/dds-loopback.xml:
 * loopback only, no multicast, unicast discovery to 127.0.0.1), as
 * palpate::dds::loopback_config() uses it. A copy of this example outside
 * palpate's build pastes that file's text instead. */
#include "palpate_loopback_config.h"

static const char* const kLoopbackConfig = PALPATE_LOOPBACK_CONFIG;

static const dds_domainid_t kDomain = 0;

/* Exits with a message when a Cyclone call fails (negative return). */
static dds_entity_t check(dds_entity_t rc, const char* what) {
  if (rc < 0) {
    fprintf(stderr, "minimal_client: %s: %s\n", what, dds_strretcode(rc));
    exit(1);
  }
  return rc;
}

/* The QoS of docs/dds.md, as palpated uses it (QoS must be compatible to match). */
static dds_qos_t* make_qos(dds_durability_kind_t durability, int32_t depth) {
  dds_qos_t* qos = dds_create_qos();
  dds_qset_reliability(qos, DDS_RELIABILITY_RELIABLE, DDS_MSECS(100));
  dds_qset_durability(qos, durability);
  dds_qset_history(qos, DDS_HISTORY_KEEP_LAST, depth);
  return qos;
}

/* Takes samples from reader until accept() returns true or timeout passes. */
static bool take_until(dds_entity_t participant, dds_entity_t reader, dds_duration_t timeout,
                       bool (*accept)(const void* sample, void* context), void* context) {
  const dds_time_t deadline = dds_time() + timeout;
  dds_entity_t waitset = check(dds_create_waitset(participant), "waitset");
  check(dds_waitset_attach(
            waitset, check(dds_create_readcondition(reader, DDS_ANY_STATE), "readcondition"), 0),
        "waitset attach");
  bool done = false;
  while (!done && dds_time() < deadline) {
    void* samples[8] = {NULL};
    dds_sample_info_t infos[8];
    const dds_return_t n = check(dds_take(reader, samples, infos, 8, 8), "take");
    for (dds_return_t i = 0; i < n && !done; ++i)
      if (infos[i].valid_data) done = accept(samples[i], context);
    if (n > 0) dds_return_loan(reader, samples, n);
    if (!done && n < 8) dds_waitset_wait_until(waitset, NULL, 0, deadline);
  }
  dds_delete(waitset);
  return done;
}

/* --- model description: remember the first compliance vertex ---------- */
struct ModelWanted {
  const char* model_id;
  bool found;
  uint32_t compliance_vertex_count;
  uint32_t first_vertex; /* mesh vertex id of the first compliance vertex */
  double rest_position[3];
};

static bool accept_model(const void* sample, void* context) {
  const palpate_ModelDescription* d = sample;
  struct ModelWanted* want = context;
  if (strcmp(d->model_id, want->model_id) != 0 || d->compliance_vertex_count == 0) return false;
  want->found = true;
  want->compliance_vertex_count = d->compliance_vertex_count;
  want->first_vertex = d->vertex_ids._buffer[0];
  for (int axis = 0; axis < 3; ++axis) want->rest_position[axis] = d->rest_positions._buffer[axis];
  return true;
}

/* --- reply: print the one that answers our request --------------------- */
struct ReplyWanted {
  uint64_t request_id;
  palpate_ReplyStatus status;
};

static bool accept_reply(const void* sample, void* context) {
  const palpate_ConstraintReply* r = sample;
  struct ReplyWanted* want = context;
  if (r->request_id != want->request_id) return false;
  want->status = r->status;
  printf("reply to request %llu on model %s: status %d%s%s\n", (unsigned long long)r->request_id,
         r->model_id, (int)r->status, r->message[0] ? ": " : "", r->message);
  printf("  condition estimate %.3g, solved in %.1f us\n", r->condition_estimate,
         (double)r->solve_ns * 1e-3);
  for (uint32_t j = 0; j < r->results._length; ++j) {
    const palpate_ConstraintResult* c = &r->results._buffer[j];
    printf(
        "  vertex %u: force (%.4g, %.4g, %.4g) N on the organ, displacement (%.4g, %.4g, %.4g) m\n",
        c->vertex, c->force[0], c->force[1], c->force[2], c->displacement[0], c->displacement[1],
        c->displacement[2]);
  }
  printf("  force to render on the haptic device: (%.4g, %.4g, %.4g) N\n", -r->total_force[0],
         -r->total_force[1], -r->total_force[2]);
  return true;
}

int main(int argc, char** argv) {
  const char* model_id = argc > 1 ? argv[1] : "sample-organ";
  const char* client_id = "minimal-client"; /* unique per client: it names the reply partition */

  /* 1. Join domain 0 with the loopback configuration (not the default one,
   *    which would use the machine's network interface). */
  const dds_entity_t domain =
      check(dds_create_domain(kDomain, kLoopbackConfig), "creating the domain");
  const dds_entity_t participant =
      check(dds_create_participant(kDomain, NULL, NULL), "creating the participant");

  /* 2. Topics, and readers and writers with palpated's QoS. */
  const dds_entity_t model_topic = check(
      dds_create_topic(participant, &palpate_ModelDescription_desc, "palpate_model", NULL, NULL),
      "topic");
  const dds_entity_t request_topic = check(
      dds_create_topic(participant, &palpate_ConstraintRequest_desc, "palpate_request", NULL, NULL),
      "topic");
  const dds_entity_t reply_topic = check(
      dds_create_topic(participant, &palpate_ConstraintReply_desc, "palpate_reply", NULL, NULL),
      "topic");

  dds_qos_t* model_qos = make_qos(DDS_DURABILITY_TRANSIENT_LOCAL, 1);
  dds_qos_t* request_qos = make_qos(DDS_DURABILITY_VOLATILE, 16);
  dds_qset_latency_budget(request_qos, 0);
  const dds_entity_t model_reader =
      check(dds_create_reader(participant, model_topic, model_qos, NULL), "model reader");
  const dds_entity_t request_writer =
      check(dds_create_writer(participant, request_topic, request_qos, NULL), "request writer");

  /* 3. The reply reader lives in this client's partition
   *    "palpate.client.<client_id>": palpated writes our replies there only. */
  char partition[128];
  snprintf(partition, sizeof partition, "palpate.client.%s", client_id);
  const char* partitions[] = {partition};
  dds_qos_t* subscriber_qos = dds_create_qos();
  dds_qset_partition(subscriber_qos, 1, partitions);
  const dds_entity_t subscriber =
      check(dds_create_subscriber(participant, subscriber_qos, NULL), "subscriber");
  const dds_entity_t reply_reader =
      check(dds_create_reader(subscriber, reply_topic, request_qos, NULL), "reply reader");

  /* 4. The model description (transient-local: it is there even if the
   *    daemon published it long ago). */
  struct ModelWanted model = {model_id, false, 0, 0, {0, 0, 0}};
  if (!take_until(participant, model_reader, DDS_SECS(10), accept_model, &model)) {
    fprintf(stderr,
            "minimal_client: no description of model '%s' within 10 s (is palpated running?)\n",
            model_id);
    return 1;
  }
  printf("model %s: %u compliance vertices; first one is mesh vertex %u at (%.4f, %.4f, %.4f) m\n",
         model_id, model.compliance_vertex_count, model.first_vertex, model.rest_position[0],
         model.rest_position[1], model.rest_position[2]);

  /* 5. Wait until palpated reads our requests AND has a reply writer matched
   *    with our reply reader; a request sent earlier may get no reply. */
  for (int waited_ms = 0;; waited_ms += 5) {
    dds_publication_matched_status_t requests;
    dds_subscription_matched_status_t replies;
    check(dds_get_publication_matched_status(request_writer, &requests), "matched status");
    check(dds_get_subscription_matched_status(reply_reader, &replies), "matched status");
    if (requests.current_count > 0 && replies.current_count > 0) break;
    if (waited_ms >= 10000) {
      fprintf(stderr, "minimal_client: palpated did not match our reply reader within 10 s\n");
      return 1;
    }
    dds_sleepfor(DDS_MSECS(5));
  }

  /* 6. One request: push the first compliance vertex 2 mm along -z. */
  palpate_Constraint constraint = {
      .vertex = model.first_vertex,
      .kind = palpate_CONSTRAINT_DISPLACEMENT,
      .value = {0.0, 0.0, -0.002}, /* m */
      .normal = {0.0, 0.0, 0.0},   /* only for palpate_CONSTRAINT_NORMAL_DISPLACEMENT */
  };
  palpate_ConstraintRequest request;
  memset(&request, 0, sizeof request);
  snprintf(request.client_id, sizeof request.client_id, "%s", client_id);
  snprintf(request.model_id, sizeof request.model_id, "%s", model_id);
  request.request_id = 1;
  request.want_surface =
      false; /* true: the reply also carries every compliance vertex's displacement */
  request.update_state = false; /* true: the result becomes what the surface stream shows */
  request.constraints._buffer = &constraint;
  request.constraints._length = request.constraints._maximum = 1;
  request.constraints._release = false;
  check(dds_write(request_writer, &request), "writing the request");

  /* 7. The reply. */
  struct ReplyWanted reply = {request.request_id, palpate_STATUS_INTERNAL_ERROR};
  if (!take_until(participant, reply_reader, DDS_SECS(5), accept_reply, &reply)) {
    fprintf(stderr, "minimal_client: no reply within 5 s\n");
    return 1;
  }

  dds_delete_qos(model_qos);
  dds_delete_qos(request_qos);
  dds_delete_qos(subscriber_qos);
  dds_delete(domain); /* deletes the participant and everything in it */
  return reply.status == palpate_STATUS_OK ? 0 : 1;
}
