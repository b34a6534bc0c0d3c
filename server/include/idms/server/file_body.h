// A Beast body that is a byte range of an open file, read in 64 KiB pieces as the socket takes
// them: a client that reads slowly (or not at all) holds one piece, never the file (a web viewer
// asset, a recording of hundreds of MB). Beast's file_body sends whole files only, so no ranges.
#pragma once

#include <boost/asio/buffer.hpp>
#include <boost/beast/core/error.hpp>
#include <boost/beast/core/file.hpp>
#include <boost/beast/http/message.hpp>
#include <boost/optional.hpp>
#include <cstdint>
#include <memory>
#include <utility>

namespace idms::server {

struct FileRangeBody {
  struct value_type {
    boost::beast::file file;  // open for reading
    uint64_t offset = 0;      // the first byte sent
    uint64_t length = 0;      // bytes sent from offset
  };

  static uint64_t size(const value_type& body) { return body.length; }

  // Reads on the connection's thread: a 64 KiB read from the page cache costs microseconds; a
  // hand-off to the worker pool per piece would cost more than it saves.
  class writer {
   public:
    using const_buffers_type = boost::asio::const_buffer;

    template <bool isRequest, class Fields>
    writer(boost::beast::http::header<isRequest, Fields>&, value_type& body) : body_(body) {}

    void init(boost::beast::error_code& ec) {
      remaining_ = body_.length;
      body_.file.seek(body_.offset, ec);
    }

    boost::optional<std::pair<const_buffers_type, bool>> get(boost::beast::error_code& ec) {
      ec = {};
      if (remaining_ == 0) return boost::none;
      if (!piece_) piece_ = std::make_unique<char[]>(kPieceBytes);
      const size_t want = static_cast<size_t>(std::min<uint64_t>(remaining_, kPieceBytes));
      const size_t got = body_.file.read(piece_.get(), want, ec);
      if (ec) return boost::none;
      // The file shrank under us: the promised Content-Length cannot be met; the connection ends.
      if (got == 0) {
        ec = boost::system::errc::make_error_code(boost::system::errc::io_error);
        return boost::none;
      }
      remaining_ -= got;
      return std::make_pair(const_buffers_type(piece_.get(), got), remaining_ > 0);
    }

   private:
    static constexpr size_t kPieceBytes = 64 << 10;
    value_type& body_;
    uint64_t remaining_ = 0;
    std::unique_ptr<char[]> piece_;  // allocated at the first piece, freed with the response
  };
};

}  // namespace idms::server
