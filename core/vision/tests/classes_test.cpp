// Vision's classes: the catalogue's real sizes, matching by size, validation.
#include "cell/vision/classes.hpp"

#include <gmock/gmock.h>
#include <gtest/gtest.h>

#include "cell/world/part_class.hpp"

namespace cell::vision {
namespace {

using ::testing::HasSubstr;

TEST(Classes, StandardCatalogueHasTheWorldsFlatClasses) {
  const ClassCatalogue c = ClassCatalogue::standard();
  const world::Catalogue world = world::Catalogue::standard();
  int flat = 0;
  for (const std::string& name : world.names()) {
    const auto cls = world.find(name);
    const PartSpec* spec = c.find(name);
    if (cls->shape == world::Shape::kBox || cls->shape == world::Shape::kPolyhedron) {
      EXPECT_EQ(spec, nullptr) << name;
      continue;
    }
    ++flat;
    ASSERT_NE(spec, nullptr) << name;
    EXPECT_DOUBLE_EQ(spec->length_mm, cls->length_mm) << name;
    EXPECT_DOUBLE_EQ(spec->top_mm, cls->height_mm) << name;
  }
  EXPECT_EQ(static_cast<int>(c.specs().size()), flat);
  const PartSpec* dip14 = c.find("dip14");
  ASSERT_NE(dip14, nullptr);
  EXPECT_EQ(dip14->shape, ShapeKind::kRectangle);
  EXPECT_DOUBLE_EQ(dip14->width_mm, 6.35);
  EXPECT_DOUBLE_EQ(dip14->top_mm, 3.81);
  EXPECT_DOUBLE_EQ(dip14->base_mm, 0.51);  // the body's walls end at the standoff
  EXPECT_EQ(dip14->pins, 14);
  EXPECT_EQ(c.find("disc")->shape, ShapeKind::kCircle);
  EXPECT_NEAR(c.find("triangle")->width_mm, 25.0 * std::sqrt(3.0) / 2.0, 1e-12);
}

TEST(Classes, TheNearestSizeWithinTheToleranceWins) {
  const ClassCatalogue c = ClassCatalogue::standard();
  // dip14 (19.05 x 6.35), dip16 (19.30 x 6.35) and ic_6x19 (19.0 x 6.0) are 0.25-0.35 mm apart.
  EXPECT_EQ(c.classify(ShapeKind::kRectangle, 19.06, 6.34, 0.45, 0.04)->spec->name, "dip14");
  EXPECT_EQ(c.classify(ShapeKind::kRectangle, 19.29, 6.36, 0.45, 0.04)->spec->name, "dip16");
  EXPECT_EQ(c.classify(ShapeKind::kRectangle, 19.01, 6.02, 0.45, 0.04)->spec->name, "ic_6x19");
  EXPECT_NEAR(c.classify(ShapeKind::kRectangle, 30.0, 7.0, 0.45, 0.04)->score, 0.0, 1e-12);
  EXPECT_FALSE(c.classify(ShapeKind::kRectangle, 45.0, 9.0, 0.45, 0.04));  // nothing that size
  EXPECT_FALSE(c.classify(ShapeKind::kCircle, 30.0, 7.0, 0.45, 0.04));
  EXPECT_EQ(c.classify(ShapeKind::kCircle, 20.1, 20.1, 0.45, 0.04)->spec->name, "disc");
  // A square is a rectangle with equal sides: either shape finds it.
  EXPECT_EQ(c.classify(ShapeKind::kRectangle, 20.05, 19.98, 0.45, 0.04)->spec->name, "square");
}

TEST(Classes, AddReplacesAndValidates) {
  ClassCatalogue c;
  EXPECT_TRUE(c.empty());
  PartSpec washer{"washer", ShapeKind::kCircle, 12.0, 12.0, 1.5, 0.0, 0};
  EXPECT_TRUE(c.add(washer));
  washer.top_mm = 2.0;
  EXPECT_TRUE(c.add(washer));
  EXPECT_EQ(c.specs().size(), 1U);
  EXPECT_DOUBLE_EQ(c.find("washer")->top_mm, 2.0);
  PartSpec bad{"oval", ShapeKind::kCircle, 12.0, 10.0, 1.0, 0.0, 0};
  auto s = c.add(bad);
  ASSERT_FALSE(s);
  EXPECT_THAT(s.error().message, HasSubstr("class 'oval': a circle has length_mm == width_mm"));
  bad = PartSpec{"thin", ShapeKind::kRectangle, 10.0, 5.0, 1.0, 1.0, 0};
  s = c.add(bad);
  ASSERT_FALSE(s);
  EXPECT_THAT(s.error().message, HasSubstr("base_mm must be in [0, top_mm = 1)"));
}

}  // namespace
}  // namespace cell::vision
