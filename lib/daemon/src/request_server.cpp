#include "request_server.hpp"

#include <fmt/format.h>
#include <spdlog/spdlog.h>

#include <algorithm>
#include <cstring>

#include "palpate/core/error.hpp"
#include "palpate/transport/wire.hpp"

namespace palpate::daemon {

RequestServer::RequestServer(const std::vector<std::unique_ptr<ServedModel>>& models,
                             std::string served_ids, ReplyWriters& replies, int max_constraints)
    : models_(models), served_ids_(std::move(served_ids)), replies_(replies) {
  std::size_t max_surface = 0;
  for (const auto& served : models)
    max_surface = std::max(max_surface, static_cast<std::size_t>(served->model.compliance_rows()));
  reply_results_.resize(static_cast<std::size_t>(max_constraints));
  reply_surface_.resize(max_surface);
  wire::use_buffers(reply_results_, reply_surface_, reply_);
  requests_.resize(kBatch);
  request_infos_.resize(kBatch);
  for (auto& r : requests_) request_pointers_.push_back(&r);
}

RequestServer::~RequestServer() {
  stop();
  // Request samples own the constraint buffers Cyclone allocated into them.
  for (auto& r : requests_) dds_sample_free(&r, &palpate_ConstraintRequest_desc, DDS_FREE_CONTENTS);
}

void RequestServer::listen(dds_entity_t participant, dds_entity_t request_topic,
                           ServingThread* serving_thread) {
  listening_.store(true, std::memory_order_release);
  dds_listener_t* listener = nullptr;
  if (serving_thread == nullptr) {
    listener = dds_create_listener(this);
    dds_lset_data_available(listener, &RequestServer::on_requests);
  }
  const dds_entity_t reader =
      dds_create_reader(participant, request_topic, dds::request_reply_qos().get(), listener);
  if (listener != nullptr) dds_delete_listener(listener);
  reader_ = dds::Entity(dds::check(reader, "creating the request reader"));
  if (serving_thread != nullptr)
    serving_thread->add(reader_.get(), &RequestServer::on_requests, this);
}

void RequestServer::stop() { reader_.reset(); }

// The listener takes from the reader Cyclone names: it may fire before
// dds_create_reader has returned, so before reader_ holds the handle (a data
// race ThreadSanitizer found; the first request then failed with a bad handle).
void RequestServer::on_requests(dds_entity_t reader, void* arg) {
  try {
    RequestServer& server = *static_cast<RequestServer*>(arg);
    (void)server.listening_.load(std::memory_order_acquire);
    server.serve(reader);
  } catch (const std::exception& e) {
    spdlog::error("event=requests_failed error=\"{}\"", e.what());
  }
}

void RequestServer::serve(dds_entity_t reader) {
  for (;;) {
    const dds_return_t n =
        dds_take(reader, request_pointers_.data(), request_infos_.data(), kBatch, kBatch);
    if (n < 0) throw SystemError(std::string("taking requests: ") + dds_strretcode(n));
    for (dds_return_t i = 0; i < n; ++i)
      if (request_infos_[i].valid_data) handle(requests_[i], request_infos_[i]);
    if (n < kBatch) return;
  }
}

RequestStatus RequestServer::solve(const palpate_ConstraintRequest& request) {
  ServedModel* served = nullptr;
  const std::string_view model_id = wire::bounded(request.model_id);
  for (const auto& candidate : models_)
    if (candidate->model.id == model_id) served = candidate.get();
  if (served == nullptr) {
    const auto end =
        fmt::format_to_n(message_, sizeof message_ - 1, "model '{}' is not served here; served: {}",
                         model_id, served_ids_);
    wire::write_message({message_, static_cast<std::size_t>(end.out - message_)}, reply_);
    return RequestStatus::kUnknownModel;
  }
  if (served->warped()) return answer(request, *served, *served->warped_solver);
  return answer(request, *served, *served->solver);
}

template <typename Solver>
RequestStatus RequestServer::answer(const palpate_ConstraintRequest& request, ServedModel& served,
                                    Solver& solver) {
  RequestStatus status = wire::load_constraints(request, solver);
  if (status == RequestStatus::kOk) status = solver.solve();
  wire::write_answer(request, status, solver,
                     static_cast<std::size_t>(served.model.compliance_rows()), reply_);
  if (status != RequestStatus::kOk) return status;
  if (request.update_state) {
    // The latest successful state-changing request defines what the model
    // shows: the vertices it loads and their forces (material ones on a
    // warped model); the stream thread does the big product.
    served.shown.show(solver.load_indices(), solver.load_forces(), {}, "",
                      wire::bounded(reply_.client_id), request.request_id, reply_.total_force);
  }
  return RequestStatus::kOk;
}

void RequestServer::handle(const palpate_ConstraintRequest& request,
                           const dds_sample_info_t& info) {
  const auto start = Clock::now();
  wire::start_reply(request, reply_);

  // A request that cannot be answered (no valid reply partition) changes nothing.
  if (!ReplyWriters::names_a_partition(reply_.client_id)) {
    stats_.count_error();
    spdlog::warn(
        "event=request_ignored client=\"{}\" request={} reason=\"client id cannot name a reply "
        "partition\"",
        reply_.client_id, request.request_id);
    return;
  }
  RequestStatus status = RequestStatus::kInternalError;
  try {
    status = solve(request);
  } catch (const std::exception& e) {
    wire::write_message(e.what(), reply_);
  }
  wire::write_status(status, reply_);
  if (status != RequestStatus::kOk) {
    stats_.count_error();
    spdlog::debug("event=request_refused client={} request={} status={} message=\"{}\"",
                  reply_.client_id, request.request_id, status_name(status), reply_.message);
  }
  replies_.send<Clock>(reply_, start);
  stats_.count_served();
  const double solve_us = static_cast<double>(reply_.solve_ns) * 1e-3;
  const double request_to_reply_us = static_cast<double>(dds_time() - info.source_timestamp) * 1e-3;
  stats_.latencies().record(solve_us, request_to_reply_us);
}

}  // namespace palpate::daemon
