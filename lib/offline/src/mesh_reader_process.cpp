// read_mesh() in a child process (mesh_io.hpp, read_mesh_isolated): Debian's
// Gmsh crashes on some damaged files (docs/fuzzing.md, "Gmsh"; reproducers
// in fuzz/reproducers/gmsh/), and a crash in the caller's process would
// end palpate-precompute with a segmentation fault instead of a message.
// The child reads the file and sends the mesh back through a pipe; the
// parent turns a child that dies into one InputError naming the file.

#include <fmt/format.h>
#include <sys/prctl.h>
#include <sys/wait.h>
#include <unistd.h>

#include <cerrno>
#include <csignal>
#include <cstdint>
#include <cstring>
#include <string>
#include <vector>

#include "palpate/core/error.hpp"
#include "palpate/offline/mesh_io.hpp"

namespace palpate {

namespace {

/// What the child sends first: the mesh, or the class of the error it threw.
enum class Outcome : std::uint8_t { kMesh, kInput, kNumerical, kResource, kSystem, kOther };

class Writer {
 public:
  explicit Writer(int fd) : fd_(fd) {}
  void bytes(const void* data, std::size_t size) {
    const auto* p = static_cast<const char*>(data);
    while (size > 0) {
      const ssize_t n = ::write(fd_, p, size);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) _exit(120);  // the parent went away: nothing to report to
      p += n;
      size -= static_cast<std::size_t>(n);
    }
  }
  template <typename T>
  void value(const T& v) {
    bytes(&v, sizeof v);
  }
  void text(const std::string& s) {
    value(static_cast<std::uint64_t>(s.size()));
    bytes(s.data(), s.size());
  }
  template <typename T>
  void array(const T* data, std::size_t count) {
    value(static_cast<std::uint64_t>(count));
    bytes(data, count * sizeof(T));
  }

 private:
  int fd_;
};

class Reader {
 public:
  explicit Reader(int fd) : fd_(fd) {}
  /// False at the end of the stream (the child died or sent everything).
  bool bytes(void* data, std::size_t size) {
    auto* p = static_cast<char*>(data);
    while (size > 0) {
      const ssize_t n = ::read(fd_, p, size);
      if (n < 0 && errno == EINTR) continue;
      if (n <= 0) return false;
      p += n;
      size -= static_cast<std::size_t>(n);
    }
    return true;
  }
  template <typename T>
  bool value(T& v) {
    return bytes(&v, sizeof v);
  }
  bool text(std::string& s) {
    std::uint64_t size = 0;
    if (!value(size) || size > (1u << 30)) return false;
    s.resize(size);
    return bytes(s.data(), size);
  }
  template <typename T>
  bool array(std::vector<T>& out) {
    std::uint64_t count = 0;
    if (!value(count) || count > (std::uint64_t{1} << 36) / sizeof(T)) return false;
    out.resize(count);
    return bytes(out.data(), count * sizeof(T));
  }

 private:
  int fd_;
};

void send_mesh(Writer& w, const TetMesh& mesh) {
  w.value(Outcome::kMesh);
  w.value(static_cast<std::int64_t>(mesh.vertices.rows()));
  w.value(static_cast<std::int64_t>(mesh.tetrahedra.rows()));
  w.bytes(mesh.vertices.data(), sizeof(double) * static_cast<std::size_t>(mesh.vertices.size()));
  w.bytes(mesh.tetrahedra.data(), sizeof(int) * static_cast<std::size_t>(mesh.tetrahedra.size()));
  w.bytes(mesh.tet_group.data(), sizeof(int) * static_cast<std::size_t>(mesh.tet_group.size()));
  w.value(static_cast<std::uint64_t>(mesh.group_names.size()));
  for (const auto& [tag, name] : mesh.group_names) {
    w.value(tag);
    w.text(name);
  }
  w.value(static_cast<std::uint64_t>(mesh.group_vertices.size()));
  for (const auto& [name, vertices] : mesh.group_vertices) {
    w.text(name);
    w.array(vertices.data(), vertices.size());
  }
  w.array(mesh.source_ids.data(), static_cast<std::size_t>(mesh.source_ids.size()));
  w.value(static_cast<std::int64_t>(mesh.source_vertex_count));
  w.text(mesh.source);
}

bool receive_mesh(Reader& r, TetMesh& mesh) {
  std::int64_t vertices = 0, tetrahedra = 0;
  if (!r.value(vertices) || !r.value(tetrahedra) || vertices < 0 || tetrahedra < 0 ||
      vertices > (std::int64_t{1} << 31) || tetrahedra > (std::int64_t{1} << 31))
    return false;
  mesh.vertices.resize(vertices, 3);
  mesh.tetrahedra.resize(tetrahedra, 4);
  mesh.tet_group.resize(tetrahedra);
  if (!r.bytes(mesh.vertices.data(), sizeof(double) * static_cast<std::size_t>(3 * vertices)) ||
      !r.bytes(mesh.tetrahedra.data(), sizeof(int) * static_cast<std::size_t>(4 * tetrahedra)) ||
      !r.bytes(mesh.tet_group.data(), sizeof(int) * static_cast<std::size_t>(tetrahedra)))
    return false;
  std::uint64_t names = 0;
  if (!r.value(names)) return false;
  for (std::uint64_t i = 0; i < names; ++i) {
    int tag = 0;
    std::string name;
    if (!r.value(tag) || !r.text(name)) return false;
    mesh.group_names[tag] = std::move(name);
  }
  std::uint64_t groups = 0;
  if (!r.value(groups)) return false;
  for (std::uint64_t i = 0; i < groups; ++i) {
    std::string name;
    std::vector<int> ids;
    if (!r.text(name) || !r.array(ids)) return false;
    mesh.group_vertices[std::move(name)] = std::move(ids);
  }
  std::vector<int> source_ids;
  std::int64_t source_vertex_count = 0;
  if (!r.array(source_ids) || !r.value(source_vertex_count) || !r.text(mesh.source)) return false;
  mesh.source_ids = Eigen::Map<const Eigen::VectorXi>(source_ids.data(),
                                                      static_cast<Eigen::Index>(source_ids.size()));
  mesh.source_vertex_count = source_vertex_count;
  return true;
}

[[noreturn]] void child(int fd, const std::filesystem::path& file, const MeshReadOptions& options) {
  Writer w(fd);
  Outcome outcome = Outcome::kOther;
  std::string message;
  try {
    const TetMesh mesh = read_mesh(file, options);
    send_mesh(w, mesh);
    ::close(fd);
    _exit(0);
  } catch (const InputError& e) {
    outcome = Outcome::kInput, message = e.what();
  } catch (const NumericalError& e) {
    outcome = Outcome::kNumerical, message = e.what();
  } catch (const ResourceError& e) {
    outcome = Outcome::kResource, message = e.what();
  } catch (const SystemError& e) {
    outcome = Outcome::kSystem, message = e.what();
  } catch (const std::bad_alloc&) {
    outcome = Outcome::kResource, message = "out of memory reading " + file.string();
  } catch (const std::exception& e) {
    outcome = Outcome::kOther, message = e.what();
  }
  w.value(outcome);
  w.text(message);
  ::close(fd);
  _exit(0);
}

}  // namespace

TetMesh read_mesh_isolated(const std::filesystem::path& file, const MeshReadOptions& options) {
  int fds[2];
  if (::pipe(fds) != 0)
    throw SystemError(
        fmt::format("reading {}: cannot make a pipe: {}", file.string(), std::strerror(errno)));
  std::fflush(nullptr);
  const pid_t parent = ::getpid();
  const pid_t pid = ::fork();
  if (pid < 0) {
    ::close(fds[0]);
    ::close(fds[1]);
    throw SystemError(fmt::format("reading {}: cannot start the reader process: {}", file.string(),
                                  std::strerror(errno)));
  }
  if (pid == 0) {
    // A killed palpate-precompute takes its reader with it, even in a long
    // read. The signal follows the forking thread, which waits here for the
    // child; a parent already gone before the prctl leaves the child to end
    // itself.
    ::prctl(PR_SET_PDEATHSIG, SIGKILL);
    if (::getppid() != parent) _exit(125);
    ::close(fds[0]);
    child(fds[1], file, options);
  }
  ::close(fds[1]);
  Reader r(fds[0]);
  Outcome outcome = Outcome::kOther;
  TetMesh mesh;
  std::string message;
  bool complete = r.value(outcome);
  if (complete) complete = outcome == Outcome::kMesh ? receive_mesh(r, mesh) : r.text(message);
  ::close(fds[0]);
  int status = 0;
  while (::waitpid(pid, &status, 0) < 0 && errno == EINTR) {
  }
  if (WIFSIGNALED(status))
    throw InputError(fmt::format(
        "{}: Gmsh crashed reading it (signal {}, {}): the file is damaged or not a mesh Gmsh "
        "can read; export it again (Gmsh .msh 2.2 or 4.1, medit .mesh, VTK, or a closed STL "
        "surface), or check it with `gmsh {} -0`",
        file.string(), WTERMSIG(status), strsignal(WTERMSIG(status)), file.string()));
  if (!complete)
    throw SystemError(fmt::format("{}: the mesh reader process ended without an answer (exit {})",
                                  file.string(), WIFEXITED(status) ? WEXITSTATUS(status) : -1));
  switch (outcome) {
    case Outcome::kMesh:
      return mesh;
    case Outcome::kInput:
      throw InputError(message);
    case Outcome::kNumerical:
      throw NumericalError(message);
    case Outcome::kResource:
      throw ResourceError(message);
    case Outcome::kSystem:
      throw SystemError(message);
    case Outcome::kOther:
      break;
  }
  throw std::logic_error(message);
}

}  // namespace palpate
