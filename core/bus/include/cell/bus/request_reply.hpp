#pragma once

#include <chrono>
#include <cstdint>
#include <string>
#include <string_view>

#include "cell/bus/reader.hpp"
#include "cell/bus/view.hpp"
#include "cell/bus/writer.hpp"

/// Request/reply over two topics, correlated by `cell_common_RequestId request_id`, which every
/// request and reply type of the contract carries. A request is never silently lost: the
/// requester learns that nobody serves the topic (kTimeout "no ... on the bus") or that no
/// reply came in time.
namespace cell::bus {

/// A client id unique across hosts, processes and calls: "<name>@<host>:<pid>.<n>.<nonce>".
std::string make_client_id(std::string_view name);

/// True when `id` names this client and sequence.
inline bool same_request(const cell_common_RequestId& id, std::string_view client_id,
                         std::uint64_t seq) noexcept {
  return id.seq == seq && str(id.client_id) == client_id;
}

/// Client side of one request/reply pair. Not thread-safe; one outstanding call at a time
/// through call(), or several through send() + wait_reply().
template <IdlType Req, IdlType Rep>
class Requester {
 public:
  Requester(const Participant& participant, const TopicDef<Req>& request_def,
            const TopicDef<Rep>& reply_def, std::string client_id)
      : client_id_(std::move(client_id)),
        request_topic_(participant, request_def),
        reply_topic_(participant, reply_def),
        writer_(participant, request_topic_, request_def),
        reader_(participant, reply_topic_, reply_def) {}

  /// Stamps request.request_id (client id, next sequence) and writes it once a server is
  /// matched. Errors: kTimeout when no reader of the request topic appears within
  /// `match_timeout`; kBus when the write fails. The stamped client_id points into this
  /// Requester: keep it alive while `request` is used.
  Result<std::uint64_t> send(Req& request, std::chrono::milliseconds match_timeout) {
    if (!writer_.wait_for_readers(1, match_timeout) ||
        !reader_.wait_for_writers(1, match_timeout)) {
      return Error{Errc::kTimeout, "no server for '" + writer_.topic_name() +
                                       "' on the bus within " +
                                       std::to_string(match_timeout.count()) + " ms"};
    }
    const std::uint64_t seq = ++seq_;
    request.request_id.client_id = borrow(client_id_);
    request.request_id.seq = seq;
    if (auto status = writer_.write(request); !status) {
      return std::move(status).error();
    }
    return seq;
  }

  /// Waits until `deadline` for a reply to `seq` for which accept(reply) holds (the first
  /// reply by default). Replies to other requests are dropped. Errors: kTimeout.
  template <typename Accept>
  Result<Owned<Rep>> wait_reply(std::uint64_t seq, std::chrono::steady_clock::time_point deadline,
                                Accept&& accept) {
    for (;;) {
      auto batch = reader_.take_copies(32);
      if (!batch) {
        return std::move(batch).error();
      }
      for (auto& reply : *batch) {
        if (same_request(reply->request_id, client_id_, seq) && accept(reply.get())) {
          return std::move(reply);
        }
      }
      if (std::chrono::steady_clock::now() >= deadline) {
        return Error{Errc::kTimeout, "no reply on '" + reader_.topic_name() + "' to request " +
                                         std::to_string(seq) + " in time"};
      }
      (void)reader_.wait_for_data(std::chrono::duration_cast<std::chrono::milliseconds>(
          deadline - std::chrono::steady_clock::now() + std::chrono::milliseconds(1)));
    }
  }

  Result<Owned<Rep>> wait_reply(std::uint64_t seq,
                                std::chrono::steady_clock::time_point deadline) {
    return wait_reply(seq, deadline, [](const Rep&) { return true; });
  }

  /// send() then wait_reply(), all within `timeout`.
  Result<Owned<Rep>> call(Req& request, std::chrono::milliseconds timeout) {
    const auto deadline = std::chrono::steady_clock::now() + timeout;
    auto seq = send(request, timeout);
    if (!seq) {
      return std::move(seq).error();
    }
    return wait_reply(*seq, deadline);
  }

  const std::string& client_id() const noexcept { return client_id_; }
  Reader<Rep>& replies() noexcept { return reader_; }
  Writer<Req>& requests() noexcept { return writer_; }

 private:
  std::string client_id_;
  std::uint64_t seq_ = 0;
  Topic<Req> request_topic_;
  Topic<Rep> reply_topic_;
  Writer<Req> writer_;
  Reader<Rep> reader_;
};

}  // namespace cell::bus
