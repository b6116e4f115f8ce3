import pytest

from alphafence.errors import InputError
from alphafence.zones.rules import load_rules


def test_default_rules_cover_the_issue_categories(rules):
    def kind_of(tags, gtype="area"):
        rule = rules.match(tags.get, gtype)
        return rule and (rule.category, rule.kind)

    assert kind_of({"aeroway": "helipad"}) == ("aerodrome", "keep_out")
    assert kind_of({"military": "bunker"}) == ("military", "keep_out")
    assert kind_of({"military": "bunker"}, "point") is None  # military=* counts for areas only
    assert kind_of({"landuse": "military"}, "point") == ("military", "keep_out")
    assert kind_of({"amenity": "kindergarten"}) == ("school", "warning")
    assert kind_of({"boundary": "protected_area"}) == ("nature", "warning")
    assert kind_of({"power": "line"}) is None
    assert kind_of({"amenity": "cafe"}) is None


def test_user_rules_file(tmp_path):
    f = tmp_path / "rules.toml"
    f.write_text(
        '[defaults]\npoint_radius_m = 12\n[[rule]]\ncategory = "zoo"\nkind = "warning"\n'
        'tags = { tourism = ["zoo"] }\nmargin_m = 5\nalt_max_m = 120\n'
    )
    rules = load_rules(f)
    rule = rules.match({"tourism": "zoo"}.get, "area")
    assert (rule.category, rule.margin_m, rule.alt_max_m, rules.point_radius_m) == (
        "zoo",
        5.0,
        120.0,
        12.0,
    )
    assert rules.keys == ("tourism",)


@pytest.mark.parametrize(
    "text, expected",
    [
        ("[[rule]]\ncategory='x'\nkind='nope'\ntags={a='*'}\n", "rule 1 (x): kind must be one of"),
        (
            "[[rule]]\ncategory='x'\nkind='warning'\ntags={a='*'}\nmargin_m=-1\n",
            "margin_m must be >= 0",
        ),
        ("[[rule]]\ncategory='x'\nkind='warning'\n", "needs tags"),
        (
            "[[rule]]\ncategory='x'\nkind='warning'\ntags={a='*'}\ncolour='red'\n",
            "unknown field(s) colour",
        ),
        ("not toml = = 1", "invalid TOML"),
    ],
)
def test_bad_rules_are_one_line_errors(tmp_path, text, expected):
    f = tmp_path / "rules.toml"
    f.write_text(text)
    with pytest.raises(InputError) as err:
        load_rules(f)
    assert str(err.value).startswith(str(f)) and expected in str(err.value)


def test_default_keep_out_margins_absorb_arducopters_own_stop_at_10_m_s(rules):
    """ArduPilot alone (FENCE_ACTION brake or RTL) stops a copter flown at 10 m/s about 21 m
    past its fence (tests/test_enforcement_sitl.py measures it): every keep-out margin of the
    default rules is at least the margin the kit documents for 10 m/s."""
    from alphafence.vehicle.params import MARGIN_FOR_SPEED_M, STOP_OVERSHOOT_M

    need = MARGIN_FOR_SPEED_M[10.0]
    assert need > STOP_OVERSHOOT_M[10.0]
    keep_out = [r for r in rules.rules if r.kind == "keep_out"]
    assert keep_out
    assert [(r.category, r.margin_m) for r in keep_out if r.margin_m < need] == []
