// SPDX-License-Identifier: GPL-3.0-or-later
// The --token check: mutating calls carry "Authorization: Bearer TOKEN" (WebSocket: ?token=).
#pragma once

#include <optional>
#include <string_view>

namespace sphles::server {

/// Compares in time that depends on the lengths only, not on where the strings differ.
bool token_equals(std::string_view expected, std::string_view given);

/// TOKEN of an "Authorization" header value "Bearer TOKEN" (scheme case-insensitive).
std::optional<std::string_view> bearer_token(std::string_view authorization);

/// True if no token is configured, or one of the offered tokens equals it.
bool authorised(std::string_view expected, std::optional<std::string_view> header_token,
                std::optional<std::string_view> query_token = std::nullopt);

}  // namespace sphles::server
