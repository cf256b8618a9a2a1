#include "gmr/skeleton/skeleton.h"

#include <gtest/gtest.h>

namespace gmr {
namespace {

Joint make(std::string name, int parent, int soft = kNoParent) {
  Joint j;
  j.name = std::move(name);
  j.parent = parent;
  j.soft_parent = soft;
  return j;
}

TEST(Validity, SkeletonCreate) {
  // Each broken input fails with a message that names the rule.
  auto expect_fail = [](std::vector<Joint> joints, const std::string& needle) {
    auto s = Skeleton::create(std::move(joints));
    ASSERT_FALSE(s.ok());
    EXPECT_NE(s.error().message.find(needle), std::string::npos) << s.error().message;
  };
  expect_fail({make("", kNoParent)}, "empty name");
  expect_fail({make("a", kNoParent), make("a", 0)}, "duplicate");
  expect_fail({make("a", kNoParent), make("b", 5)}, "out of range");
  expect_fail({make("a", 1), make("b", kNoParent)}, "before its child");
  expect_fail({make("a", kNoParent), make("b", 0, 0)}, "only a root");
  expect_fail({make("a", kNoParent), make("b", kNoParent, 1)}, "soft link");
  Joint twice = make("a", kNoParent);
  twice.channels = {ChannelType::kXrotation, ChannelType::kXrotation};
  expect_fail({twice}, "listed twice");
  // The valid case.
  EXPECT_TRUE(Skeleton::create({make("a", kNoParent), make("b", 0)}).ok());
}

TEST(MultiRoots, Skeleton) {
  //   a       d (soft link -> b)
  //  / \      |
  // b   c     e
  std::vector<Joint> j = {make("a", kNoParent), make("b", 0), make("c", 0), make("d", kNoParent, 1), make("e", 3)};
  j[0].channels = {ChannelType::kXposition, ChannelType::kZrotation};
  j[4].channels = {ChannelType::kYrotation};
  auto s = Skeleton::create(j);
  ASSERT_TRUE(s.ok());
  EXPECT_EQ(s->roots(), (std::vector<int>{0, 3}));
  EXPECT_EQ(std::vector<int>(s->children(0).begin(), s->children(0).end()), (std::vector<int>{1, 2}));
  EXPECT_TRUE(s->children(1).empty());
  EXPECT_EQ(s->root_of(4), 3);
  EXPECT_EQ(s->depth(4), 1);
  EXPECT_EQ(s->find("e"), 4);
  EXPECT_EQ(s->find("zz"), -1);
  EXPECT_EQ(s->channel_count(), 3);
  EXPECT_EQ(s->channel_offset(4), 2);
}

TEST(Empty, Skeleton) {
  auto s = Skeleton::create({});
  ASSERT_TRUE(s.ok());
  EXPECT_TRUE(s->empty());
  EXPECT_TRUE(s->roots().empty());
  EXPECT_EQ(s->channel_count(), 0);
}

}  // namespace
}  // namespace gmr
