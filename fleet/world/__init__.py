"""The warehouse: layouts as data (docs/layouts.md), their checks, generated floors, and places
named the way users write them."""
