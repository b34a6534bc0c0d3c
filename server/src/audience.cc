// A session's viewers on this server (audience.h).
#include "audience.h"

#include "sessions.h"

namespace idms::server {

using Clock = std::chrono::steady_clock;

namespace {
constexpr uint16_t kPolicyError = 1008;
}

void Audience::Add(uint64_t id, std::weak_ptr<WsPeer> peer, bool admin,
                   std::shared_ptr<std::atomic<bool>> drain_wanted) {
  Viewer& v = viewers_.emplace_back();
  v.id = id;
  v.peer = std::move(peer);
  v.admin = admin;
  v.drain_wanted = std::move(drain_wanted);
}

bool Audience::Remove(uint64_t id) {
  return std::erase_if(viewers_, [&](const Viewer& v) { return v.id == id; }) > 0;
}

void Audience::Offer(Outgoing& out) {
  for (Viewer& v : viewers_) {
    const std::shared_ptr<WsPeer> peer = v.peer.lock();
    if (!peer || v.closed) continue;
    if (out.deltas > 0 && v.skipping) {
      hub_.deltas_skipped += out.deltas;
      if (!out.made) {
        out.made = true;
        if (out.without_deltas_maker) out.without_deltas = out.without_deltas_maker();
      }
      if (!out.without_deltas) continue;
    }
    if (peer->queued() >= kQueueLimit || peer->queued_bytes() >= kQueueBytes) {
      // Behind: a viewer stalled past the limit is closed; until then it loses deltas (and is
      // resynchronised with a keyframe once it drains), sample batches and events (counted).
      const auto now = Clock::now();
      if (!v.behind_since) v.behind_since = now;
      const std::chrono::seconds limit = core_.options.viewer_stall_timeout;
      if (now - *v.behind_since > limit) {
        ++hub_.stalled_closed;
        v.closed = true;
        peer->Close(kPolicyError, "viewer stalled: more than " + std::to_string(kQueueLimit) + " frames or " +
                                      std::to_string(kQueueBytes >> 20) + " MiB behind for " +
                                      std::to_string(limit.count()) + " s");
        continue;
      }
      if (out.deltas > 0 && !v.skipping) {
        hub_.deltas_skipped += out.deltas;
        v.skipping = true;
        v.drain_wanted->store(true);
      }
      hub_.samples_dropped += out.samples;
      hub_.events_dropped += out.others;
      continue;
    }
    v.behind_since.reset();
    Send(v, out.deltas > 0 && v.skipping ? out.without_deltas : out.bytes);
  }
}

void Audience::Send(Viewer& v, const Bytes& bytes) {
  const std::shared_ptr<WsPeer> peer = v.peer.lock();
  if (!peer || v.closed) return;
  ++hub_.viewer_frames;
  hub_.viewer_bytes += bytes->size();
  peer->Send(bytes, true);
}

void Audience::SendTo(uint64_t id, const Bytes& bytes) {
  for (Viewer& v : viewers_) {
    if (v.id == id) Send(v, bytes);
  }
}

void Audience::SendToAll(const Bytes& bytes) {
  for (Viewer& v : viewers_) Send(v, bytes);
}

void Audience::Greet(uint64_t id, const Bytes& welcome, const Bytes& keyframe) {
  SendTo(id, welcome);
  if (keyframe) SendTo(id, keyframe), ++hub_.resyncs;
  for (const Bytes& bytes : history_) SendTo(id, bytes);
}

void Audience::Remember(const Bytes& bytes) {
  history_.push_back(bytes);
  history_bytes_ += bytes->size();
  while (history_.size() > kHistoryFrames || history_bytes_ > kHistoryBytes) {
    history_bytes_ -= history_.front()->size();
    history_.pop_front();
  }
}

void Audience::ForgetHistory() {
  history_.clear();
  history_bytes_ = 0;
}

void Audience::Drained(uint64_t id, const std::function<Bytes()>& keyframe) {
  for (Viewer& v : viewers_) {
    if (v.id != id || !v.skipping) continue;
    if (const Bytes k = keyframe()) {
      v.skipping = false;
      ++hub_.resyncs;
      Send(v, k);
    }
  }
}

void Audience::Resync(const Bytes& keyframe) {
  for (Viewer& v : viewers_) {
    v.skipping = false;
    ++hub_.resyncs;
    Send(v, keyframe);
  }
}

void Audience::CloseAll(uint16_t code, const std::string& why) {
  for (Viewer& v : viewers_) {
    if (auto peer = v.peer.lock()) peer->Close(code, why);
  }
  viewers_.clear();
}

std::shared_ptr<const std::string> KeyframeOf(MeshMirror& mirror) {
  v1::Envelope e;
  std::string error;
  if (!mirror.has_keyframe() || !mirror.MakeKeyframe(e.mutable_mesh_keyframe(), &error)) return nullptr;
  return Serialized(e);
}

}  // namespace idms::server
