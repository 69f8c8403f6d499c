#pragma once
// Private to palpate_device: the C++ object behind the C API's opaque handle
// (palpate/device.h): one tool on one model driven by one device, the
// device's frame, the poses sent, and the log of the answers taken. The
// extern "C" functions of device.cpp check their arguments and drive it.

#include <Eigen/Geometry>
#include <array>
#include <cstdint>
#include <string>

#include "palpate/core/ring.hpp"
#include "palpate/device.h"
#include "palpate/transport/tool_client.hpp"

/// One tool on one model, driven by one device.
struct palpate_device {
  palpate_device(const palpate::ToolClientOptions& client_options) : client(client_options) {}

  palpate::ToolClient client;
  std::string model_id, tool_id;
  palpate::ModelInfo model;

  // The device's frame in the model's (palpate_device_frame).
  double scale = 1, force_scale = 1;
  Eigen::Quaterniond rotation = Eigen::Quaterniond::Identity();
  Eigen::Quaterniond handle_to_tool = Eigen::Quaterniond::Identity();
  Eigen::Vector3d offset = Eigen::Vector3d::Zero();

  // Poses: the last one given (model frame), and those sent.
  bool has_pose = false;
  std::array<double, 3> position{};
  std::array<double, 4> orientation{1, 0, 0, 0};
  double jaw = 0;
  std::int64_t period_ns = 1'000'000, next_due_ns = 0;
  std::uint64_t first_sequence = 0, sequence = 0, poses_sent = 0;
  std::int64_t last_send_ns = 0;
  bool session_live = false;

  // Answers: the next sequence the drain asks for, the newest, the log.
  std::uint64_t next_sequence = 0;
  bool has_answer = false;
  palpate::ToolFeedbackSample newest;
  std::uint64_t answers_taken = 0, answers_dropped = 0;
  palpate::Ring<palpate_device_answer, 256> answers;
  std::array<palpate::ToolFeedbackSample, 16> late{};

  palpate::RenderedWrench rendered;
  Eigen::Vector3d rendered_force = Eigen::Vector3d::Zero();
  Eigen::Vector3d rendered_torque = Eigen::Vector3d::Zero();

  palpate::Ring<palpate_device_event, 64> events;

  /// Answer @p s into the log (the oldest dropped when it is full), and the
  /// newest kept. Allocates nothing.
  void took(const palpate::ToolFeedbackSample& s);

  /// Every answer the client took (render() keeps them for their wait) or
  /// that is waiting in DDS, into the log, without waiting. Allocates nothing.
  void drain();
};
