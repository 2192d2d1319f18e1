// SPDX-License-Identifier: GPL-3.0-or-later
// The compiled parts of Asio and Beast, once for all of sphles (BOOST_ASIO_SEPARATE_COMPILATION,
// BOOST_BEAST_SEPARATE_COMPILATION in server/CMakeLists.txt).
#include <boost/asio/impl/src.hpp>
#include <boost/beast/src.hpp>
