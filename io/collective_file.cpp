// SPDX-License-Identifier: GPL-3.0-or-later
#include "io/collective_file.hpp"

#include <algorithm>
#include <mutex>
#include <system_error>

#include "io/checkpoint_error.hpp"
#include "io/hdf5_file.hpp"
#include "io/hdf5_library.hpp"

namespace sphles::io::detail {

namespace {

/// The longest failure message the ranks exchange (agree()).
constexpr std::size_t kMaxMessageBytes = std::size_t{1} << 16;

}  // namespace

PlainCommunicator::PlainCommunicator(MPI_Comm from) {
  int rank = 0;
  MPI_Comm_rank(from, &rank);
  MPI_Comm_split(from, 0, rank, &comm);
}

PlainCommunicator::~PlainCommunicator() {
  MPI_Comm_free(&comm);
}

std::optional<std::string> agree(MPI_Comm comm, const std::optional<std::string>& failure) {
  int rank = 0, size = 1;
  MPI_Comm_rank(comm, &rank);
  MPI_Comm_size(comm, &size);
  const int mine = failure ? rank : size;
  int lowest = size;
  MPI_Allreduce(&mine, &lowest, 1, MPI_INT, MPI_MIN, comm);
  if (lowest == size) return std::nullopt;
  int length = rank == lowest ? static_cast<int>(std::min(failure->size(), kMaxMessageBytes)) : 0;
  MPI_Bcast(&length, 1, MPI_INT, lowest, comm);
  std::string text = rank == lowest ? failure->substr(0, static_cast<std::size_t>(length))
                                    : std::string(static_cast<std::size_t>(length), '\0');
  MPI_Bcast(text.data(), length, MPI_CHAR, lowest, comm);
  return text;
}

void fail_agreed(MPI_Comm comm, const std::filesystem::path& path,
                 const std::optional<std::string>& failure) {
  if (!failure) return;
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  std::error_code ignored;  // the temporary may not exist yet
  if (rank == 0) std::filesystem::remove(temporary_name(path), ignored);
  throw CheckpointError(*failure);
}

void write_collectively(MPI_Comm comm, const std::filesystem::path& path, const std::string& label,
                        std::uint64_t bound,
                        const std::function<void(hid_t file, hid_t transfer)>& contents) {
  int rank = 0;
  MPI_Comm_rank(comm, &rank);
  const auto fail = [&](const std::optional<std::string>& failure) {
    fail_agreed(comm, path, failure);
  };
  // Room for the file before HDF5 touches the disk: every process' file-size limit, the file
  // system's free space (rank 0, which names the temporary: its PID).
  std::string temporary = temporary_name(path);
  int length = static_cast<int>(temporary.size());
  MPI_Bcast(&length, 1, MPI_INT, 0, comm);
  temporary.resize(static_cast<std::size_t>(length));
  MPI_Bcast(temporary.data(), length, MPI_CHAR, 0, comm);
  fail(agree(comm, attempt([&] {
               check_file_size_limit(bound, label);
               if (rank == 0) check_free_space(path, bound, label);
             })));

  const PlainCommunicator plain(comm);
  const std::lock_guard lock(hdf5_library_mutex());
  silence_hdf5();
  const Handle access(H5Pcreate(H5P_FILE_ACCESS), H5Pclose);
  const Handle transfer(H5Pcreate(H5P_DATASET_XFER), H5Pclose);
  const bool properties = access.valid() && transfer.valid() &&
                          H5Pset_fapl_mpio(access.get(), plain.comm, MPI_INFO_NULL) >= 0 &&
                          H5Pset_coll_metadata_write(access.get(), true) >= 0 &&
                          H5Pset_dxpl_mpio(transfer.get(), H5FD_MPIO_COLLECTIVE) >= 0;
  fail(agree(comm, properties ? std::nullopt
                              : std::optional<std::string>(
                                    label + ": cannot set up the MPI-IO file access properties")));
  // Opening is collective in MPI-IO: it succeeds or fails on every process alike.
  hid_t file = H5Fcreate(temporary.c_str(), H5F_ACC_TRUNC, H5P_DEFAULT, access.get());
  fail(agree(comm, file >= 0 ? std::nullopt
                             : std::optional<std::string>(label + ": cannot create '" + temporary +
                                                          "' through MPI-IO")));
  // The temporary's blocks reserved, then the contents written; each step agreed, so that no
  // process enters a collective call the others have left.
  std::optional<std::string> failure = agree(comm, attempt([&] {
                                               if (rank == 0)
                                                 reserve_space(temporary, bound, label);
                                             }));
  if (!failure) failure = agree(comm, attempt([&] { contents(file, transfer.get()); }));
  const bool closed = H5Fclose(file) >= 0;
  if (!failure)
    failure = agree(
        comm, closed ? std::nullopt
                     : std::optional<std::string>(label + ": cannot close '" + temporary + "'"));
  fail(failure);
  fail(agree(comm, attempt([&] {
               if (rank == 0) commit_temporary(temporary, path, label);
             })));
}

}  // namespace sphles::io::detail
