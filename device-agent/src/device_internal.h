// Device constructors shared between the device sources (not part of the agent's API).
#pragma once

#include <memory>
#include <string>
#include <string_view>

#include "idms/agent/device.h"

namespace idms::agent {

// udp:ARGS, ARGS = PORT[,bind=ADDR][,timeout_ms=T]; binds the socket. tick_s: the loop period
// (the timeout is counted in ticks). Null and *error on failure.
std::unique_ptr<Device> MakeUdpDevice(std::string_view args, double tick_s, std::string* error);

// replay:PATH — the /device channel of an idms session recording (MCAP), read whole now, played
// back in simulated time. Positions are in the model frame; the registration maps them back.
std::unique_ptr<Device> MakeReplayDevice(std::string_view path, const Registration& registration, std::string* error);

}  // namespace idms::agent
