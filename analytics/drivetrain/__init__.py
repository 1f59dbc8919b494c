"""The drivetrain a mill is: its configuration and the physics derived from it.

Modules::

    mill_config      MillConfig: one validated, frozen description of a mill (TOML → pydantic)
    kinematics       expected excitation lines (orders, frequencies) of a steady spectrum
    stress           volts → strain → stress, section moduli, combined stress (seed 000 App. D)
    torsional_model  lumped torsional model: natural frequencies, resonance warnings, dynamic
                     factor meter (seed 001)

Data flow: everything else reads a :class:`~analytics.drivetrain.mill_config.MillConfig` and
asks these modules for rated torques, stresses and expected lines; nothing here holds samples
except the small DynamicFactorMeter. A new config field goes in ``mill_config`` (with its
validation and a clear error naming the field); a new physical model gets its own module here.
"""
