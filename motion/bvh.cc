#include "motion/bvh.h"

#include <cmath>
#include <cstdio>
#include <cstdlib>
#include <fstream>
#include <functional>
#include <sstream>

#include "common/file_util.h"
#include "common/json_util.h"

namespace perch {
namespace {

struct Token {
  std::string text;
  int line;
};

class HierarchyParser {
 public:
  HierarchyParser(std::vector<Token> toks, const std::string& source, int eof_line)
      : t_(std::move(toks)), src_(source), eof_line_(eof_line) {}

  void Parse(BvhClip* clip) {
    Expect("HIERARCHY");
    Expect("ROOT");
    ParseJoint(clip, -1, false);
    if (pos_ != t_.size()) Fail(t_[pos_].line, "unexpected '" + t_[pos_].text + "' after ROOT");
  }

 private:
  [[noreturn]] void Fail(int line, const std::string& msg) const {
    throw ConfigError(src_ + ":" + std::to_string(line) + ": " + msg);
  }
  const Token& Next(const char* what) {
    if (pos_ >= t_.size()) Fail(eof_line_, std::string("truncated file: expected ") + what);
    return t_[pos_++];
  }
  void Expect(const std::string& word) {
    const Token& tok = Next(("'" + word + "'").c_str());
    if (tok.text != word) Fail(tok.line, "expected '" + word + "', got '" + tok.text + "'");
  }
  double Number(const char* what) {
    const Token& tok = Next(what);
    char* end = nullptr;
    const double v = std::strtod(tok.text.c_str(), &end);
    if (end == tok.text.c_str() || *end != '\0' || !std::isfinite(v)) {
      Fail(tok.line, std::string("expected ") + what + ", got '" + tok.text + "'");
    }
    return v;
  }
  Eigen::Vector3d Offset() {
    Expect("OFFSET");
    Eigen::Vector3d o;
    for (int i = 0; i < 3; ++i) o[i] = Number("an OFFSET value");
    return o;
  }

  void ParseJoint(BvhClip* clip, int parent, bool end_site) {
    BvhJoint j;
    j.parent = parent;
    j.end_site = end_site;
    if (end_site) {
      Expect("Site");
      j.name = clip->joints[parent].name + "_End";
    } else {
      j.name = Next("a joint name").text;
      if (j.name == "{") Fail(t_[pos_ - 1].line, "missing joint name");
    }
    Expect("{");
    j.offset = Offset();
    const int index = static_cast<int>(clip->joints.size());
    if (!end_site) {
      const Token& ch = Next("'CHANNELS'");
      if (ch.text != "CHANNELS") Fail(ch.line, "expected 'CHANNELS', got '" + ch.text + "'");
      const Token& nt = Next("a channel count");
      char* end = nullptr;
      const long n = std::strtol(nt.text.c_str(), &end, 10);
      if (*end != '\0' || n < 0 || n > 6) Fail(nt.line, "bad channel count '" + nt.text + "'");
      j.first_channel = clip->num_channels;
      for (long i = 0; i < n; ++i) {
        const Token& c = Next("a channel name");
        static const char* kNames[] = {"Xposition", "Yposition", "Zposition",
                                       "Xrotation", "Yrotation", "Zrotation"};
        int k = 0;
        while (k < 6 && c.text != kNames[k]) ++k;
        if (k == 6) Fail(c.line, "unknown channel '" + c.text + "'");
        j.channels.push_back(static_cast<BvhChannel>(k));
      }
      clip->num_channels += static_cast<int>(n);
    }
    clip->joints.push_back(j);
    while (true) {
      const Token& tok = Next("'}'");
      if (tok.text == "}") return;
      if (end_site) Fail(tok.line, "unexpected '" + tok.text + "' in End Site");
      if (tok.text == "JOINT") {
        ParseJoint(clip, index, false);
      } else if (tok.text == "End") {
        ParseJoint(clip, index, true);
      } else {
        Fail(tok.line, "unknown keyword '" + tok.text + "' (expected JOINT, End or })");
      }
    }
  }

  std::vector<Token> t_;
  size_t pos_ = 0;
  const std::string& src_;
  int eof_line_;
};

std::string Trim(const std::string& s) {
  const size_t a = s.find_first_not_of(" \t\r");
  if (a == std::string::npos) return "";
  const size_t b = s.find_last_not_of(" \t\r");
  return s.substr(a, b - a + 1);
}

Eigen::Matrix3d AxisRot(BvhChannel c, double deg) {
  const double a = deg * M_PI / 180.0;
  Eigen::Vector3d axis = c == BvhChannel::kXrot   ? Eigen::Vector3d::UnitX()
                         : c == BvhChannel::kYrot ? Eigen::Vector3d::UnitY()
                                                  : Eigen::Vector3d::UnitZ();
  return Eigen::AngleAxisd(a, axis).toRotationMatrix();
}

}  // namespace

int BvhClip::Find(const std::string& name) const {
  for (size_t i = 0; i < joints.size(); ++i) {
    if (joints[i].name == name) return static_cast<int>(i);
  }
  return -1;
}

BvhClip ParseBvh(const std::string& text, const std::string& source) {
  // Split into lines; the hierarchy is tokenised up to the MOTION line.
  std::vector<std::string> lines;
  {
    std::istringstream in(text);
    std::string l;
    while (std::getline(in, l)) lines.push_back(l);
  }
  auto fail = [&](int line, const std::string& msg) {
    throw ConfigError(source + ":" + std::to_string(line) + ": " + msg);
  };
  size_t motion = 0;
  std::vector<Token> toks;
  for (; motion < lines.size(); ++motion) {
    if (Trim(lines[motion]) == "MOTION") break;
    std::string l = lines[motion];
    std::string spaced;
    for (char c : l) {
      if (c == '{' || c == '}') {
        spaced += ' ';
        spaced += c;
        spaced += ' ';
      } else {
        spaced += c;
      }
    }
    std::istringstream ls(spaced);
    std::string w;
    while (ls >> w) toks.push_back({w, static_cast<int>(motion) + 1});
  }
  BvhClip clip;
  HierarchyParser(std::move(toks), source, static_cast<int>(motion) + 1).Parse(&clip);
  if (motion >= lines.size()) fail(static_cast<int>(lines.size()), "truncated file: no MOTION");
  // "Frames: N" and "Frame Time: t".
  size_t li = motion + 1;
  auto header = [&](const std::string& key) -> std::string {
    if (li >= lines.size())
      fail(static_cast<int>(lines.size()), "truncated file: no '" + key + "'");
    const std::string l = Trim(lines[li]);
    if (l.compare(0, key.size(), key) != 0) {
      fail(static_cast<int>(li) + 1, "expected '" + key + "', got '" + l + "'");
    }
    ++li;
    return Trim(l.substr(key.size()));
  };
  const std::string fs = header("Frames:");
  char* end = nullptr;
  const long nframes = std::strtol(fs.c_str(), &end, 10);
  if (fs.empty() || *end != '\0' || nframes < 0)
    fail(static_cast<int>(li), "bad frame count '" + fs + "'");
  const std::string ft = header("Frame Time:");
  clip.frame_time = std::strtod(ft.c_str(), &end);
  if (ft.empty() || *end != '\0' || !(clip.frame_time > 0)) {
    fail(static_cast<int>(li), "bad frame time '" + ft + "'");
  }
  clip.frames.resize(nframes, clip.num_channels);
  long f = 0;
  for (; li < lines.size() && f < nframes; ++li) {
    const std::string l = Trim(lines[li]);
    const int lineno = static_cast<int>(li) + 1;
    if (l.empty())
      fail(lineno, "empty line inside the motion data (frame " + std::to_string(f) + ")");
    const char* p = l.c_str();
    int k = 0;
    while (*p) {
      char* e = nullptr;
      const double v = std::strtod(p, &e);
      if (e == p || (*e && *e != ' ' && *e != '\t')) {
        fail(lineno, "bad number in frame " + std::to_string(f) + " near '" +
                         std::string(p).substr(0, 16) + "'");
      }
      if (!std::isfinite(v)) fail(lineno, "non-finite value in frame " + std::to_string(f));
      if (k < clip.num_channels) clip.frames(f, k) = v;
      ++k;
      p = e;
      while (*p == ' ' || *p == '\t') ++p;
    }
    if (k != clip.num_channels) {
      fail(lineno, "frame " + std::to_string(f) + " has " + std::to_string(k) +
                       " values, expected " + std::to_string(clip.num_channels));
    }
    ++f;
  }
  if (f < nframes) {
    fail(static_cast<int>(lines.size()),
         "truncated file: header says Frames: " + std::to_string(nframes) + " but only " +
             std::to_string(f) + " frame lines follow");
  }
  for (; li < lines.size(); ++li) {
    if (!Trim(lines[li]).empty()) {
      fail(static_cast<int>(li) + 1,
           "more frame lines than 'Frames: " + std::to_string(nframes) + "'");
    }
  }
  return clip;
}

BvhClip ReadBvhFile(const std::string& path) { return ParseBvh(ReadFileBytes(path), path); }

std::string WriteBvh(const BvhClip& clip) {
  static const char* kNames[] = {"Xposition", "Yposition", "Zposition",
                                 "Xrotation", "Yrotation", "Zrotation"};
  std::ostringstream o;
  o.precision(9);
  o << "HIERARCHY\n";
  // Children of each joint, in order.
  const int n = static_cast<int>(clip.joints.size());
  std::vector<std::vector<int>> kids(n);
  for (int i = 0; i < n; ++i) {
    if (clip.joints[i].parent >= 0) kids[clip.joints[i].parent].push_back(i);
  }
  std::function<void(int, int)> emit = [&](int i, int depth) {
    const BvhJoint& j = clip.joints[i];
    const std::string ind(depth, '\t');
    if (j.end_site) {
      o << ind << "End Site\n";
    } else {
      o << ind << (j.parent < 0 ? "ROOT " : "JOINT ") << j.name << "\n";
    }
    o << ind << "{\n"
      << ind << "\tOFFSET " << j.offset.x() << " " << j.offset.y() << " " << j.offset.z() << "\n";
    if (!j.end_site) {
      o << ind << "\tCHANNELS " << j.channels.size();
      for (BvhChannel c : j.channels) o << " " << kNames[static_cast<int>(c)];
      o << "\n";
    }
    for (int k : kids[i]) emit(k, depth + 1);
    o << ind << "}\n";
  };
  for (int i = 0; i < n; ++i) {
    if (clip.joints[i].parent < 0) emit(i, 0);
  }
  o << "MOTION\nFrames: " << clip.frames.rows() << "\nFrame Time: " << clip.frame_time << "\n";
  for (int f = 0; f < clip.frames.rows(); ++f) {
    for (int c = 0; c < clip.frames.cols(); ++c) o << (c ? " " : "") << clip.frames(f, c);
    o << "\n";
  }
  return o.str();
}

void SaveBvhFile(const std::string& path, const BvhClip& clip) {
  WriteFileAtomic(path, WriteBvh(clip));
}

Eigen::Matrix3d BvhLocalRotation(const BvhJoint& j, const double* row) {
  Eigen::Matrix3d r = Eigen::Matrix3d::Identity();
  for (size_t c = 0; c < j.channels.size(); ++c) {
    const BvhChannel ch = j.channels[c];
    if (ch == BvhChannel::kXrot || ch == BvhChannel::kYrot || ch == BvhChannel::kZrot) {
      r = r * AxisRot(ch, row[j.first_channel + c]);
    }
  }
  return r;
}

BvhPose BvhForwardKinematics(const BvhClip& clip, const Eigen::VectorXd& values) {
  const int n = static_cast<int>(clip.joints.size());
  BvhPose p;
  p.pos.resize(n);
  p.rot.resize(n);
  for (int i = 0; i < n; ++i) {
    const BvhJoint& j = clip.joints[i];
    Eigen::Vector3d t = j.offset;
    for (size_t c = 0; c < j.channels.size(); ++c) {
      const int k = static_cast<int>(j.channels[c]);
      if (k < 3) t[k] += values[j.first_channel + c];
    }
    const Eigen::Matrix3d r = BvhLocalRotation(j, values.data());
    if (j.parent < 0) {
      p.pos[i] = t;
      p.rot[i] = r;
    } else {
      p.pos[i] = p.pos[j.parent] + p.rot[j.parent] * t;
      p.rot[i] = p.rot[j.parent] * r;
    }
  }
  return p;
}

BvhPose BvhForwardKinematics(const BvhClip& clip, int frame) {
  return BvhForwardKinematics(clip, Eigen::VectorXd(clip.frames.row(frame).transpose()));
}

}  // namespace perch
