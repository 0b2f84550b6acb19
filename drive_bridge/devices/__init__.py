"""Device families: register maps as data, decode/encode, trip tables. No I/O."""
