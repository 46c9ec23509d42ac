"""The composition root's builders: one plant construction for every simulated bus."""

from __future__ import annotations

import numpy as np
import pytest

from drivers.cia402.drive_group import DriveGroup
from drivers.sim.esc.network import EmulatedNetwork
from drivers.sim.simbus import SimBus
from drivers.transport import BACKENDS
from hofto_hw.config.models import SystemConfig
from hofto_hw.errors import ConfigError
from hofto_hw.runtime import build


def test_plant_ticks_at_the_bus_cycle_and_quiet_drops_external_torques(er3a_config) -> None:
    plant = build.build_plant(er3a_config, external=False)
    assert (
        plant.dt
        == build.cycle_time(er3a_config)
        == er3a_config.cycle_time
        == 1.0 / er3a_config.loop.rate_hz
    )
    assert plant.external.evaluate(1.0, plant.q, plant.qd).tolist() == [0.0] * 6
    loud = build.build_plant(er3a_config)
    assert any(
        np.any(loud.external.evaluate(t, loud.q, loud.qd) != 0.0) for t in np.arange(0, 20, 0.05)
    )


def test_sim_bus_and_emulated_network_share_the_same_plant_construction(er3a_config) -> None:
    bus = build.build_sim_bus(er3a_config, external=False)
    net = build.build_emulated_network(er3a_config, external=False)
    assert isinstance(bus, SimBus) and isinstance(net, EmulatedNetwork)
    assert bus.axis_names == list(er3a_config.robot.joints)
    p1, p2 = bus.plant, net.drives.plant
    assert p1.dt == p2.dt
    np.testing.assert_array_equal(p1.q, p2.q)
    # the same seeded "true" arm: identical perturbed inertias
    for a, b in zip(
        p1.true_model.pin_model.inertias, p2.true_model.pin_model.inertias, strict=True
    ):
        assert a.mass == b.mass
    ident = [(s.desc.vendor_id, s.desc.product_code) for s in net.slaves]
    assert ident == [
        (d.identity.vendor_id, d.identity.product_code) for d in er3a_config.bus.drives
    ]


def test_transport_is_looked_up_in_the_backend_registry(er3a_config) -> None:
    t = build.build_transport(er3a_config)
    assert er3a_config.bus.transport == "sim" and "sim" in BACKENDS
    assert isinstance(t, SimBus)
    group = build.build_drive_group(er3a_config, t)
    assert isinstance(group, DriveGroup) and group.n == 6


def test_ethercat_transport_from_config_is_not_opened(er3a_config) -> None:
    from drivers.ethercat.master import EtherCATTransport

    bus = er3a_config.bus.model_copy(update={"transport": "ethercat", "interface": "ecm0"})
    t = build.build_transport(er3a_config.model_copy(update={"bus": bus}))
    assert isinstance(t, EtherCATTransport)
    assert t.interface == "ecm0" and not t.is_open and t.cycle_time == er3a_config.cycle_time


def test_unknown_transport_names_the_field_and_the_backends(er3a_config) -> None:
    bus = er3a_config.bus.model_copy(update={"transport": "profibus"})
    with pytest.raises(ConfigError, match=r"bus\.transport: unknown transport 'profibus' \(known"):
        build.build_transport(er3a_config.model_copy(update={"bus": bus}))


@pytest.mark.parametrize(
    "builder",
    [build.build_sim_bus, build.build_emulated_network, build.build_transport],
)
def test_config_without_bus_is_a_clear_error(builder, er3a_config: SystemConfig) -> None:
    with pytest.raises(ConfigError, match="bus: section missing"):
        builder(er3a_config.model_copy(update={"bus": None}))
