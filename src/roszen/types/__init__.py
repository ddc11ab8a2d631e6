"""roszen type support: .msg/.srv specs, generated classes, CDR, RIHS01 hashes, dict/YAML."""
