"""The drivetrain a mill is: its configuration and the physics derived from it.

Modules::

    mill_config      MillConfig: one validated, frozen description of a mill (TOML → pydantic),
                     with each component's S-N curve and mean-stress correction
                     ([material.components]), the Miner limit ([life]) and the simulator's
                     condition of a simulated mill ([simulation])
    kinematics       expected excitation lines (orders, frequencies) of a steady spectrum
    stress           volts → strain → stress, section moduli, combined stress (Diering 2011 App. D)
    start_limits     start-peak set points per starter type: mean + 2 / + 3 standard deviations
                     of Diering 2011 Tables 3–11, capped at the motor shaft's absolute limit
    shaft_stress     ShaftStressModel: the fatigue factors K_f of bending and torsion and the
                     local combined stress rainflow counts (Diering 2011 §8.1–8.2, App. D) on
                     one plane θ or the critical plane's grid
    torsional_params TorsionalParams: the [torsional] table of a mill file (Fedin & Vinogradov
                     2018 Table 2, referred to the pinion shaft)
    torsional_model  lumped torsional model: natural frequencies (natural_frequencies_of a
                     mill), resonance warnings, the model in words, dynamic factor meter

Data flow: everything else reads a :class:`~millwatch.analytics.drivetrain.mill_config.MillConfig`
and asks these modules for rated torques, stresses and expected lines; nothing here holds samples
except the small DynamicFactorMeter. A new config field goes in ``mill_config`` (with its
validation and a clear error naming the field); a new physical model gets its own module here.
"""
