// The layout (layout/taxel_layout.hpp): what TaxelLayout::validate refuses, by name.
#include <doctest/doctest.h>

#include <cmath>

#include <tjepa/layout/taxel_layout.hpp>
#include <tjepa/sensors/layout_builder.hpp>

TEST_SUITE("layout") {
  TEST_CASE("TaxelLayout::validate names duplicate ids - NaN coordinates and foreign groups") {
    tjepa::LayoutBuilder b;
    const int p = b.add_part("p");
    b.add_grid_pad("g", p, tjepa::GridPad(2, 2));
    tjepa::TaxelLayout l = b.layout();
    CHECK_NOTHROW(l.validate());
    auto dup = l;
    dup.ids[2] = dup.ids[0];
    CHECK_THROWS_WITH_AS(dup.validate(), doctest::Contains("duplicate taxel id 0"), tjepa::DataError);
    auto nan = l;
    nan.coords[3] = std::nan("");
    CHECK_THROWS_WITH_AS(nan.validate(), doctest::Contains("non-finite coordinate"), tjepa::DataError);
    auto foreign = l;
    foreign.part_names.push_back("q");
    foreign.group_names.push_back("h");
    foreign.group_part.push_back(1);
    foreign.part[1] = 1;
    CHECK_THROWS_WITH_AS(foreign.validate(), doctest::Contains("belongs to part 'p'"), tjepa::DataError);
    auto range = l;
    range.group[0] = 7;
    CHECK_THROWS_WITH_AS(range.validate(), doctest::Contains("has group 7"), tjepa::DataError);
  }
}
