// The body type of the server's HTTP responses: text the response owns, or a read-only view of
// text shared with other responses and WebSocket messages (a serialised analysis product, built
// once per frame by server/product_cache.hpp). Sharing means a hundred readers of a large
// product hold one copy of it, not a hundred.
#pragma once

#include <boost/asio/buffer.hpp>
#include <boost/beast/core/error.hpp>
#include <boost/beast/http/message.hpp>
#include <boost/optional.hpp>
#include <cstdint>
#include <memory>
#include <string>
#include <string_view>
#include <utility>

namespace sphles::server {

struct TextBody {
  class value_type {
   public:
    value_type() = default;
    value_type& operator=(std::string text) {
      owned_ = std::move(text);
      shared_.reset();
      return *this;
    }
    /// The body becomes `text` (not copied; kept alive by this body).
    void share(std::shared_ptr<const std::string> text) {
      owned_.clear();
      shared_ = std::move(text);
    }
    std::string_view view() const { return shared_ ? std::string_view(*shared_) : owned_; }
    std::size_t size() const { return view().size(); }
    bool empty() const { return size() == 0; }
    void clear() {
      owned_.clear();
      shared_.reset();
    }
    /// Bytes this response holds on its own (a shared text is counted once, by its owner).
    std::size_t owned_bytes() const { return shared_ ? 0 : owned_.size(); }

   private:
    std::string owned_;
    std::shared_ptr<const std::string> shared_;
  };

  static std::uint64_t size(const value_type& body) { return body.size(); }

  /// Beast's BodyWriter: the whole text as one buffer.
  class writer {
   public:
    using const_buffers_type = boost::asio::const_buffer;
    template <bool isRequest, class Fields>
    writer(const boost::beast::http::header<isRequest, Fields>&, const value_type& body)
        : body_(body) {}
    void init(boost::beast::error_code& ec) { ec = {}; }
    boost::optional<std::pair<const_buffers_type, bool>> get(boost::beast::error_code& ec) {
      ec = {};
      const std::string_view text = body_.view();
      return {{const_buffers_type(text.data(), text.size()), false}};
    }

   private:
    const value_type& body_;
  };
};

}  // namespace sphles::server
