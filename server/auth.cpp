// SPDX-License-Identifier: GPL-3.0-or-later
#include "server/auth.hpp"

#include <cctype>

namespace sphles::server {

bool token_equals(std::string_view expected, std::string_view given) {
  if (expected.empty()) return false;  // an empty token never matches
  std::size_t difference = expected.size() ^ given.size();
  for (std::size_t i = 0; i < given.size(); ++i)
    difference |= static_cast<unsigned char>(given[i]) ^
                  static_cast<unsigned char>(expected[i % expected.size()]);
  return difference == 0;
}

std::optional<std::string_view> bearer_token(std::string_view authorization) {
  constexpr std::string_view scheme = "bearer ";
  if (authorization.size() <= scheme.size()) return std::nullopt;
  for (std::size_t i = 0; i < scheme.size(); ++i)
    if (std::tolower(static_cast<unsigned char>(authorization[i])) != scheme[i])
      return std::nullopt;
  std::string_view token = authorization.substr(scheme.size());
  while (!token.empty() && (token.front() == ' ' || token.front() == '\t')) token.remove_prefix(1);
  while (!token.empty() && (token.back() == ' ' || token.back() == '\t')) token.remove_suffix(1);
  if (token.empty()) return std::nullopt;
  return token;
}

bool authorised(std::string_view expected, std::optional<std::string_view> header_token,
                std::optional<std::string_view> query_token) {
  if (expected.empty()) return true;
  bool ok = false;
  if (header_token) ok |= token_equals(expected, *header_token);
  if (query_token) ok |= token_equals(expected, *query_token);
  return ok;
}

}  // namespace sphles::server
