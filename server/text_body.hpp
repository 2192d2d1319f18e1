// The body type of the server's HTTP responses: text the response owns, or a read-only view of
// text shared with other responses and WebSocket messages (a serialised analysis product, built
// once per frame by server/product_cache.hpp), or a file streamed from disk in chunks (the run
// files' downloads, of any size). Sharing means a hundred readers of a large product hold one
// copy of it, not a hundred; streaming means a checkpoint of gigabytes is never held at all.
#pragma once

#include <fcntl.h>
#include <sys/stat.h>
#include <unistd.h>

#include <algorithm>
#include <boost/asio/buffer.hpp>
#include <boost/beast/core/error.hpp>
#include <boost/beast/http/message.hpp>
#include <boost/optional.hpp>
#include <cerrno>
#include <cstdint>
#include <filesystem>
#include <memory>
#include <string>
#include <string_view>
#include <system_error>
#include <utility>
#include <vector>

namespace sphles::server {

/// An open regular file and its size when opened (bytes appended later are not sent; a file
/// replaced or removed meanwhile is still read whole: the descriptor keeps it).
class FileSource {
 public:
  static std::shared_ptr<const FileSource> open(const std::filesystem::path& file,
                                                std::error_code& ec) {
    const int fd = ::open(file.c_str(), O_RDONLY | O_CLOEXEC | O_NOFOLLOW);
    struct stat st {};
    if (fd < 0 || ::fstat(fd, &st) != 0 || !S_ISREG(st.st_mode)) {
      ec = std::error_code(fd < 0 ? errno : EISDIR, std::generic_category());
      if (fd >= 0) ::close(fd);
      return nullptr;
    }
    ec = {};
    return std::shared_ptr<const FileSource>(
        new FileSource(fd, static_cast<std::uint64_t>(st.st_size)));
  }
  ~FileSource() { ::close(fd_); }
  FileSource(const FileSource&) = delete;
  FileSource& operator=(const FileSource&) = delete;
  std::uint64_t size() const { return size_; }
  /// Up to `n` bytes at `offset` into `out`; the count read, or -1 on an error.
  ssize_t read(char* out, std::size_t n, std::uint64_t offset) const {
    ssize_t got;
    do {
      got = ::pread(fd_, out, n, static_cast<off_t>(offset));
    } while (got < 0 && errno == EINTR);
    return got;
  }

 private:
  FileSource(int fd, std::uint64_t size) : fd_(fd), size_(size) {}
  int fd_;
  std::uint64_t size_;
};

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
    /// The body becomes the file's bytes, read from disk as they are sent.
    void stream(std::shared_ptr<const FileSource> file) {
      clear();
      file_ = std::move(file);
    }
    const FileSource* file() const { return file_.get(); }
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
    std::shared_ptr<const FileSource> file_;
  };

  static std::uint64_t size(const value_type& body) { return body.size(); }

  /// Beast's BodyWriter: the whole text as one buffer, or the file in chunks.
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
      const FileSource* file = body_.file();
      if (!file) {
        const std::string_view text = body_.view();
        return {{const_buffers_type(text.data(), text.size()), false}};
      }
      const std::uint64_t remaining = file->size() - offset_;
      if (remaining == 0) return boost::none;
      chunk_.resize(static_cast<std::size_t>(std::min<std::uint64_t>(kChunkBytes, remaining)));
      const ssize_t got = file->read(chunk_.data(), chunk_.size(), offset_);
      if (got <= 0) {  // an error, or the file was truncated under the response
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
