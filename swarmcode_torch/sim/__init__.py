"""The world: scenarios, hardware phenotypes, layouts, behavior trees and the batched tick.

Knows nothing of genomes or evolution (imports only torch and itself)."""
