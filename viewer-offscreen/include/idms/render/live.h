// A live session watched as a viewer (/ws/session/{id}): the Welcome's scene, then keyframes,
// deltas and device batches applied to a ViewerState, as the web viewer does.
#pragma once

#include <functional>
#include <string>

#include "idms/render/source.h"

namespace idms::render {

struct LiveOptions {
  std::string url;        // http://HOST:PORT or ws://HOST:PORT (no TLS)
  std::string session;    // the session id
  std::string token;      // a bearer token (observer or above)
  double timeout_s = 15;  // for the connection and for each frame
};

// Connects, then calls on_update after each mesh frame applied (the state has a surface) until
// it returns false or the session ends. False with *error when the connection fails, the server
// refuses, or a frame is malformed; true when on_update stopped it or the session ended.
bool WatchLive(const LiveOptions& options, ViewerState* state, const std::function<bool(const ViewerState&)>& on_update,
               std::string* error);

}  // namespace idms::render
