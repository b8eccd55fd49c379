"""What energy costs: a fuel's tariff (`tariff.py`) and the month's bill with its demand charges (`bill.py`)."""
