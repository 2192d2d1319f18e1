// SPDX-License-Identifier: GPL-3.0-or-later
// The body type of the server's HTTP responses: text the response owns, or a read-only view of
// text shared with other responses and WebSocket messages (a serialised analysis product, built
// once per frame by server/product_cache.hpp), or bytes streamed from disk in chunks (a ByteSource:
// the run files' downloads and a whole run's archive, of any size). Sharing means a hundred readers
// of a large product hold one copy of it, not a hundred; streaming means a checkpoint of gigabytes
// is never held at all.
#pragma once

#include <algorithm>
#include <boost/asio/buffer.hpp>
#include <boost/beast/core/error.hpp>
#include <boost/beast/http/message.hpp>
#include <boost/optional.hpp>
#include <cerrno>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <utility>
#include <vector>

#include "server/byte_source.hpp"

namespace sphles::server {

struct TextBody {
  class value_type {
   public:
    value_type() = default;
    value_type& operator=(std::string text) {
      clear();
      owned_ = std::move(text);
      return *this;
    }
    /// The body becomes `text` (not copied; kept alive by this body).
    void share(std::shared_ptr<const std::string> text) {
      clear();
      shared_ = std::move(text);
    }
    /// The body becomes the source's bytes, read from disk as they are sent.
    void stream(std::shared_ptr<const ByteSource> file) {
      clear();
      file_ = std::move(file);
    }
    const ByteSource* file() const { return file_.get(); }
    /// The text (empty for a streamed file).
    std::string_view view() const { return shared_ ? std::string_view(*shared_) : owned_; }
    std::size_t size() const {
      return file_ ? static_cast<std::size_t>(file_->size()) : view().size();
    }
    bool empty() const { return size() == 0; }
    void clear() {
      owned_.clear();
      shared_.reset();
      file_.reset();
    }
    /// Bytes this response holds in memory on its own (a shared text is counted once, by its
    /// owner; a streamed file holds one chunk at a time).
    std::size_t owned_bytes() const { return shared_ || file_ ? 0 : owned_.size(); }

   private:
    std::string owned_;
    std::shared_ptr<const std::string> shared_;
    std::shared_ptr<const ByteSource> file_;
  };

  static std::uint64_t size(const value_type& body) { return body.size(); }

  /// Beast's BodyWriter: the whole text as one buffer, or the source in chunks.
  class writer {
   public:
    using const_buffers_type = boost::asio::const_buffer;
    static constexpr std::size_t kChunkBytes = 256u << 10;
    template <bool isRequest, class Fields>
    writer(const boost::beast::http::header<isRequest, Fields>&, const value_type& body)
        : body_(body) {}
    void init(boost::beast::error_code& ec) { ec = {}; }
    boost::optional<std::pair<const_buffers_type, bool>> get(boost::beast::error_code& ec) {
      ec = {};
      const ByteSource* file = body_.file();
      if (!file) {
        const std::string_view text = body_.view();
        return {{const_buffers_type(text.data(), text.size()), false}};
      }
      const std::uint64_t remaining = file->size() - offset_;
      if (remaining == 0) return boost::none;
      chunk_.resize(static_cast<std::size_t>(std::min<std::uint64_t>(kChunkBytes, remaining)));
      const ssize_t got = file->read(chunk_.data(), chunk_.size(), offset_);
      if (got <= 0) {  // an error, or a file was truncated under the response
        ec = boost::beast::error_code(got < 0 ? errno : EIO, boost::system::generic_category());
        return boost::none;
      }
      offset_ += static_cast<std::uint64_t>(got);
      return {{const_buffers_type(chunk_.data(), static_cast<std::size_t>(got)),
               offset_ < file->size()}};
    }

   private:
    const value_type& body_;
    std::uint64_t offset_ = 0;
    std::vector<char> chunk_;
  };
};

}  // namespace sphles::server
